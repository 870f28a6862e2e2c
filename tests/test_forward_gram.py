"""identify/forward.py: a forward-difference Jacobian's Gram matrix summed over a record in time blocks equals the
whole Jacobian's J'J, J'r, r'r (held-out entries, observed masks and profiled offsets included), without the (D, R)
array."""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest

from vehid_cli.diagnose.holdout import holdout_blocks, masked
from vehid_cli.identify.experiment import Experiment
from vehid_cli.identify.forward import forward_gram
from vehid_cli.optimizers.compressed import compress, compress_gram


def _task(offsets: bool, seconds: float):
    from tests.conftest import BASE_CONFIG
    from vehid_cli.config import load_config
    from vehid_cli.identify.task import build_task

    sets = ["identify.objective=wls", "noise.level=0.03", f"simulation.duration={seconds}",
            "simulation.integrator=rk4", "identify.truth=config"]  # fmt: skip
    task = dataclasses.replace(build_task(load_config(BASE_CONFIG, sets)), offsets=offsets)
    task = task.with_unknowns(("kf", "kr", "cf", "cr"))  # D = 9, as a diagnosis's re-fit
    ref = task.reference(0)
    if offsets:  # a channel sampled every other row: observed masks, the objective's own entries
        observed = {f: np.ones(v.shape, dtype=bool) for f, v in ref.items()}
        observed["acc"][1::2, 2] = False
        task = dataclasses.replace(task, observed=observed)
    return task, ref


def _points(task) -> tuple[np.ndarray, np.ndarray]:
    x = task.nominal * np.random.default_rng(3).uniform(0.98, 1.02, task.dim)
    step = 1e-6 * x * np.where(np.arange(task.dim) % 2, 1.0, -1.0)
    return np.vstack([x[None, :], x[None, :] + np.diag(step)]), step


def _relative(G: np.ndarray, want: np.ndarray) -> float:
    """The largest difference of G from `want`, entry by entry relative to sqrt(want_ii want_jj)."""
    d = np.sqrt(np.diag(want))
    return float(np.max(np.abs(G - want) / np.outer(d, d)))


@pytest.mark.parametrize("offsets", [False, True])
def test_blocked_sums_equal_the_whole_jacobians(monkeypatch, offsets):
    """On a record of three blocks, with a hold-out split (and observed masks and profiled offsets): the Gram matrix
    of [J r] summed block by block equals the one of the whole residual vectors' forward differences at the kept
    entries, to 1e-9 of each entry's scale, and its compressed pair gives the same J'J, J'r, r'r as `compress`'s;
    through the masked problem's hook (a long record's) the same, with the cars split over threads or not."""
    task, ref = _task(offsets, 5)
    assert task.experiment.t.size > 2 * 2048  # several blocks
    problem = task.problem(ref)
    X, step = _points(task)
    _, R = problem.residuals(X)
    keep = ~np.resize(holdout_blocks(R.shape[1] // 2), R.shape[1])
    R = R[:, keep]
    J = (R[1:] - R[0]) / step[:, None]
    A = np.vstack([J, R[:1]])
    want = A @ A.T
    rows = np.flatnonzero(keep)
    G = forward_gram(task.experiment, task.objective(ref), {n: X[:, j] for j, n in enumerate(task.names)}, step, rows)
    assert _relative(G, want) < 1e-9
    rj, z, rho = compress_gram(G)
    rj0, z0, rho0 = compress(J, R[0])
    np.testing.assert_allclose(rj.T @ rj, rj0.T @ rj0, rtol=1e-8, atol=1e-9 * np.max(np.abs(rj0.T @ rj0)))
    np.testing.assert_allclose(rj.T @ z, rj0.T @ z0, rtol=1e-8, atol=1e-9 * np.max(np.abs(rj0.T @ z0)))
    assert abs(z @ z + rho**2 - (z0 @ z0 + rho0**2)) < 1e-10 * (z0 @ z0 + rho0**2)
    assert problem.gram(X, step, rows) is None  # a short record: its Jacobian is held, today's path
    monkeypatch.setattr(Experiment, "long", property(lambda self: True))
    monkeypatch.setattr(Experiment, "blocked", lambda self, values=None: True)
    assert _relative(masked(problem, keep).gram(X, step, None), want) < 1e-9
    monkeypatch.setattr("vehid_cli.identify.forward.available_cores", lambda: 1)
    assert _relative(masked(problem, keep).gram(X, step, None), want) < 1e-9


def test_blocked_sums_hold_no_record_sized_jacobian():
    """The sums' traced peak does not grow with the record as the (D, R_kept) Jacobian they replace does: from 10 to
    40 s (5 to 20 blocks) it grows by less than a quarter of the Jacobian's growth, where the residuals of the D + 1
    cars (the usual way to form J) grow by more than all of it."""

    def traced_peak(run, *args) -> int:
        tracemalloc.start()
        try:
            run(*args)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    peaks = []
    for seconds in (10, 40):
        task, ref = _task(True, seconds)
        problem = task.problem(ref)
        X, step = _points(task)
        keep = ~np.resize(holdout_blocks(task.residual_samples // 2), task.residual_samples)
        rows = np.flatnonzero(keep)
        objective = task.objective(ref)
        values = {n: X[:, j] for j, n in enumerate(task.names)}
        forward_gram(task.experiment, objective, values, step, rows)  # compiled, cached
        blocked = traced_peak(forward_gram, task.experiment, objective, values, step, rows)
        whole = traced_peak(problem.kept, X, rows)
        peaks.append((task.dim * rows.size * 8, blocked, whole))
    (j10, b10, w10), (j40, b40, w40) = peaks
    assert w40 - w10 > j40 - j10  # the check can fail: the usual way is caught by it
    assert b40 - b10 < (j40 - j10) / 4


def _faulty_task(tmp_path, *unknowns: str, start: dict[str, float]):
    """The diagnosis's task on a 5 s run of the paper's car recorded through a faulty chain (acc2 upside down, acc3
    and acc4 swapped, acc1 read 0.1 m/s² high), with those corrections and kf as unknowns."""
    from tests.conftest import BASE_CONFIG
    from vehid_cli.config import load_config
    from vehid_cli.identify.task import build_tasks
    from vehid_cli.systems import write_simulation

    sets = ["identify.objective=wls", "noise.level=0.03", "simulation.duration=5", "simulation.integrator=rk4"]
    path = tmp_path / "run.csv"
    write_simulation(load_config(BASE_CONFIG, sets), path, seed=7)
    lines = path.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    head = lines[first].split(",")
    a1, a2, a3, a4 = (head.index(c) for c in ("acc1", "acc2", "acc3", "acc4"))
    rows = [line.split(",") for line in lines[first + 1 :]]
    for row in rows:
        row[a1], row[a2] = repr(float(row[a1]) + 0.1), repr(-float(row[a2]))
        row[a3], row[a4] = row[a4], row[a3]
    path.write_text("\n".join(lines[: first + 1] + [",".join(r) for r in rows]) + "\n")
    task = build_tasks(load_config(BASE_CONFIG, sets), (path,))
    limits = {"sensor:acc2:sign": (-3.0, -0.3), "sensor:acc3:swap:acc4": (0.0, 1.0),
              "sensor:acc1:offset": (-1.0, 1.0), "sensor:acc3:delay": (-0.05, 0.05)}  # fmt: skip
    return task.with_unknowns(("kf", *unknowns), limits=limits, start=start)


def test_blocked_sums_apply_the_measurement_chains_corrections(tmp_path, monkeypatch):
    """A fit that carries corrections of the chain (a sign, a swap, an offset: each reads only its own samples) has
    its Gram matrix summed block by block as well, each block's channels corrected alone: the same as the whole
    residual vectors' forward differences to 1e-9; a delay, which reads other samples, leaves it to the held
    Jacobian (no sums) and forward_gram refuses it."""
    names = ("sensor:acc2:sign", "sensor:acc3:swap:acc4", "sensor:acc1:offset")
    task = _faulty_task(tmp_path, *names, start=dict(zip(names, (-1.0, 0.9, 0.1), strict=True)))
    assert len(task.corrections) == 3
    ref = task.reference(0)
    X, step = _points(task)
    X[:, -3:] = [-0.97, 0.93, 0.08]  # the corrections away from their null, as a fit has them
    X[1:, -3:] += np.diag(step)[:, -3:]
    _, R = task.problem(ref).residuals(X)
    A = np.vstack([(R[1:] - R[0]) / step[:, None], R[:1]])
    want = A @ A.T
    values = {n: X[:, j] for j, n in enumerate(task.names)}
    G = forward_gram(task.experiment, task.objective(ref), values, step, None, task.corrections)
    assert _relative(G, want) < 1e-9
    uncorrected = forward_gram(task.experiment, task.objective(ref), values, step)  # the corrections matter here
    assert _relative(uncorrected, want) > 1e-3
    monkeypatch.setattr(Experiment, "long", property(lambda self: True))
    monkeypatch.setattr(Experiment, "blocked", lambda self, values=None: True)
    assert _relative(task.problem(ref).gram(X, step, None), want) < 1e-9
    delayed = _faulty_task(tmp_path, "sensor:acc3:delay", start={"sensor:acc3:delay": 0.0})
    Xd, sd = _points(delayed)
    assert delayed.problem(ref).gram(Xd, sd, None) is None
    with pytest.raises(ValueError, match="block by block"):
        forward_gram(delayed.experiment, delayed.objective(ref), {n: Xd[:, j] for j, n in enumerate(delayed.names)},
                     sd, None, delayed.corrections)  # fmt: skip
