"""The damper models' fast path (every candidate of a batch at once: ``models.damper.*_lanes`` through
``sim.prescribed.lanes_loop``) against the reference path (each model's scalar law, one candidate after the other,
``simulate_damper(reference=True)``, itself checked against closed forms and an adaptive ODE solver in
tests/test_damper.py): the same forces bit for bit, for every model the config can name, with backlash, control lag,
delays, control steps, substeps and candidates that differ in every parameter; and the delayed command against the
NumPy statement of its definition."""

from __future__ import annotations

import numpy as np
import pytest

from vehid_cli.models.bench import sawtooth, sine
from vehid_cli.models.damper import BW_SET, MODELS, default_values
from vehid_cli.sim.bench import delayed_controls, simulate_damper
from vehid_cli.systems.damper.fit import DamperSpec

BW = dict(c0=1500.0, k0=500.0, c1=20000.0, alpha=800.0, beta=3e5, gamma=3e5, delta=200.0)
LAG = dict(T_comp_rise=0.01, T_comp_fall=0.012, T_reb_rise=0.02, T_reb_fall=0.015)
DELAY = dict(tau_comp_rise=0.003, tau_comp_fall=0.004, tau_reb_rise=0.01, tau_reb_fall=0.005)


def force_map_values(nv: int, nu: int) -> dict[str, float]:
    """A force map rising in velocity and in u (nodes over +-0.3 m/s, beyond the sine's peak at the ends)."""
    v = {f"v_node_{i + 1}": x for i, x in enumerate(np.linspace(-0.3, 0.3, nv))}
    v.update({f"u_node_{j + 1}": x for j, x in enumerate(np.linspace(0.0, 1.0, nu))})
    v.update({f"F_{i + 1}_{j + 1}": 3000.0 * (i - nv // 2) * (1 + j) for i in range(nv) for j in range(nu)})
    return v


def generalized_values(m: int) -> dict[str, float]:
    """Bouc-Wen sets that differ between compression and rebound and along the m nodes over u."""
    return {
        f"{p}_{side}" + (f"_{j + 1}" if m > 1 else ""): BW[p] * (1 + 0.3 * j) * (1.2 if side == "reb" else 1.0)
        for p in BW_SET
        for side in ("comp", "reb")
        for j in range(m)
    }


CASES = {
    "gas_spring": ("gas_spring", (), dict(k1=2000.0, x0=-0.01)),
    "viscous": ("viscous", (), dict(c0=1500.0, k1=100.0)),
    "bingham": ("bingham", (), dict(c0=700.0, fc=80.0, v_eps=0.01)),
    "bouc_wen": ("bouc_wen", (), BW),
    "bouc_wen + backlash": ("bouc_wen", (), dict(BW, gap=0.002, k1=500.0)),
    "generalized_bouc_wen (1)": ("generalized_bouc_wen", (1,), dict(generalized_values(1), **LAG, **DELAY)),
    "generalized_bouc_wen (3) + backlash": (
        "generalized_bouc_wen", (3,), dict(generalized_values(3), **LAG, **DELAY, gap=0.001)
    ),
    "force_map (5 x 3)": ("force_map", (5, 3), dict(force_map_values(5, 3), **LAG, **DELAY)),
    "force_map (4 x 4), lag rising only": (
        "force_map", (4, 4), dict(force_map_values(4, 4), T_reb_rise=0.02, T_comp_rise=0.02)
    ),
}  # fmt: skip


def batch(model: str, table: tuple[int, ...], values: dict, size: int, seed: int) -> tuple[DamperSpec, np.ndarray]:
    """The spec and `size` rows: the first as configured, the others with every parameter (table sizes and nodes
    kept) moved by up to +-10 %, so that no two candidates share a value (and the caches of the batch law miss)."""
    v = default_values(model, table)
    v.update(values)
    spec = DamperSpec(model, v, table)
    rows = np.repeat(spec.row()[None, :], size, axis=0)
    rng = np.random.default_rng(seed)
    vary = [i for i, n in enumerate(spec.names) if n not in ("m", "nv", "nu") and "node" not in n]
    rows[1:, vary] *= 1 + 0.2 * (rng.random((size - 1, len(vary))) - 0.5)
    return spec, rows


def test_every_model_the_config_names_has_a_batch_law():
    assert set(MODELS) == {m for m, _, _ in CASES.values()}
    assert all(m.lanes is not None for m in MODELS.values())


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("substeps", [1, 3])
def test_the_batch_law_gives_the_reference_forces_bit_for_bit(case, substeps):
    model, table, values = CASES[case]
    spec, rows = batch(model, table, values, 6, seed=len(case))
    for h in (sine(0.025, 0.8, 1.2, 1e-3), sawtooth(cycles=1.5)):  # the sawtooth steps the command
        ref = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u, substeps, reference=True)
        new = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u, substeps)
        assert ref.stable.all()  # the comparison is of forces, not of NaNs
        assert np.array_equal(new.force, ref.force), np.max(np.abs(new.force - ref.force))
        assert np.array_equal(new.stable, ref.stable)


@pytest.mark.parametrize("case", ["bouc_wen", "generalized_bouc_wen (3) + backlash", "force_map (5 x 3)"])
def test_a_candidate_gets_the_same_force_in_any_batch(case):
    """The batch law's caches (the switch of Eq. 5 shared with the candidate before, the cells of the tables) never
    leak from one candidate to another: each candidate alone gives its force in the batch, bit for bit."""
    model, table, values = CASES[case]
    spec, rows = batch(model, table, values, 5, seed=1)
    rows[2] = rows[1]  # two equal neighbours share the switch; the others do not
    h = sawtooth(cycles=1.5)
    together = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u).force
    for r in range(len(rows)):
        alone = simulate_damper(spec.damper, rows[r : r + 1], h.t, h.x, h.v, h.u).force[0]
        assert np.array_equal(alone, together[r])


def test_candidates_whose_nodes_differ_look_their_tables_up_one_by_one():
    """The generalised model's look-up takes the fourteen tables over the whole batch when every candidate's u fell in
    the same cell, candidate by candidate otherwise: nodes that differ between the candidates (and lags that settle
    at different times) send the batch through both, and each agrees with the reference bit for bit."""
    model, table, values = CASES["generalized_bouc_wen (3) + backlash"]
    spec, rows = batch(model, table, values, 6, seed=3)
    middle = spec.names.index("u_node_2")
    rows[:, middle] = np.linspace(0.2, 0.45, len(rows))  # the sawtooth's steps (0.15 <-> 0.5) cross them in turn
    h = sawtooth(cycles=1.5)
    ref = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u, reference=True)
    new = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u)
    assert ref.stable.all()
    assert np.array_equal(new.force, ref.force), np.max(np.abs(new.force - ref.force))


@pytest.mark.parametrize("nu", [3, 17])
def test_the_force_maps_look_up_at_its_end_nodes_and_past_its_kept_reciprocals(nu):
    """The force map's look-up of u: nodes whose intervals are not powers of two, the sawtooth's command (0.15 <-> 0.5)
    beyond the last node (held at its end value: its last interval x is one where x (1 / x) misses 1, so that value
    must be the node's own, not one reached through a fraction) and, with 17 nodes, more intervals than the batch law
    keeps reciprocals of (16 > 12: the rest taken at each look-up): the reference's forces bit for bit."""
    nodes = [float(v) for v in np.linspace(0.0, 0.3, nu - 1) ** 1.3]
    misses = (nodes[-1] + x for x in np.arange(0.1, 0.2, 1e-4) if (d := nodes[-1] + x - nodes[-1]) * (1.0 / d) != 1.0)
    last = float(next(misses))
    x = last - nodes[-1]
    assert x * (1.0 / x) != 1.0
    values = force_map_values(5, nu)
    values.update({f"u_node_{j + 1}": v for j, v in enumerate(nodes + [last])})
    spec, rows = batch("force_map", (5, nu), dict(values, **LAG, **DELAY), 6, seed=nu)
    h = sawtooth(cycles=1.5)
    ref = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u, reference=True)
    new = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u)
    assert ref.stable.all()
    assert np.array_equal(new.force, ref.force), np.max(np.abs(new.force - ref.force))


def test_an_unstable_candidate_is_flagged_and_leaves_the_others_alone():
    model, table, values = CASES["bouc_wen"]
    spec, rows = batch(model, table, values, 4, seed=2)
    rows[1, spec.names.index("c1")] = 1e-9  # c0 + c1 tiny: Bouc-Wen's internal rate explodes at a 1 ms step
    rows[1, spec.names.index("c0")] = 0.0
    h = sine(0.025, 0.8, 1.2, 1e-3)
    ref = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u, reference=True)
    new = simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u)
    assert list(new.stable) == [True, False, True, True] == list(ref.stable)
    assert np.all(np.isnan(new.force[1]))
    assert np.array_equal(new.force[[0, 2, 3]], ref.force[[0, 2, 3]])


def delayed_by_definition(t, u, v, tau4):
    """The delayed command written from its definition (sim/bench.delayed_controls' docstring), one candidate: each
    change of u, as a one-sample ramp starting at its sample's time - dt + its delay (never before an earlier
    change's start), in NumPy; and the direction of the latest change whose ramp is complete."""
    dt = t[1] - t[0]
    change = np.diff(u, prepend=u[0])
    moved = np.flatnonzero(change)
    which = np.where(v[moved] > 0, 2, 0) + np.where(change[moved] > 0, 0, 1)
    start = np.maximum.accumulate(t[moved] - dt + tau4[which])
    level = np.full(t.size, u[0])
    for s, jump in zip(start, change[moved], strict=True):
        level = level + jump * np.clip((t - s) / dt, 0.0, 1.0)
    done = np.searchsorted(start + dt, t, side="right") - 1
    rising = np.where(done >= 0, (change[moved] > 0)[np.maximum(done, 0)], True).astype(float)
    return level, rising


def test_the_delayed_command_is_its_definition():
    h = sawtooth(cycles=3.0)
    u = h.u.copy()
    u[1500:1560] = 0.9  # a change that a long delay makes overtake the next: merged
    rng = np.random.default_rng(4)
    delays = rng.random((5, 4)) * 0.03
    delays[4] = [0.0, 0.05, 0.0, 0.05]  # falling changes 50 ms late: later than the rise that follows
    out = delayed_controls(h.t, u, h.v, delays)
    for p in range(len(delays)):
        level, rising = delayed_by_definition(h.t, u, h.v, delays[p])
        np.testing.assert_allclose(out[p, :, 0], level, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(out[p, :, 1], rising)
    same = delayed_controls(h.t, u, h.v, np.repeat(delays[:1], 3, axis=0))  # shared delays: computed once
    assert np.array_equal(same, np.repeat(out[:1], 3, axis=0))


@pytest.mark.parametrize("seed", range(6))
def test_the_delayed_command_is_its_definition_for_random_steps(seed):
    """The walk computes only the samples around each change (sim/bench._ramps) and copies the row before elsewhere:
    random step commands (steps a sample apart, a change's ramp crossing the next one's, steps at the first and last
    samples), random delays per candidate from 0 to 60 ms, each candidate against the definition."""
    rng = np.random.default_rng(seed)
    h = sawtooth(cycles=2.0)
    u = np.full(h.t.size, rng.uniform(0, 1))
    for k in np.sort(rng.integers(1, h.t.size, rng.integers(1, 12))):
        u[k:] = rng.uniform(0, 1)
    u[rng.integers(1, h.t.size - 1) :][:2] = rng.uniform(0, 1, 1)  # two changes one sample apart
    u[-1] = rng.uniform(0, 1)  # a change at the last sample
    delays = rng.random((int(rng.integers(2, 9)), 4)) * rng.choice([1e-3, 1e-2, 6e-2])
    out = delayed_controls(h.t, u, h.v, delays)
    for p in range(len(delays)):
        level, rising = delayed_by_definition(h.t, u, h.v, delays[p])
        np.testing.assert_allclose(out[p, :, 0], level, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(out[p, :, 1], rising)
