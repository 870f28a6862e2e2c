"""The fast exact path (modal recursions) against the NumPy reference of the same discretisation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from tests.conftest import PAPER_CAR
from tests.reference import rel_rms
from tests.test_linear import paper_road
from vehid_cli.config import load_config
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.io.measurement import time_grid
from vehid_cli.models.fullcar import VEHICLE_PARAMETERS, assemble
from vehid_cli.models.sensors import Layout, Sensor, corner_layout
from vehid_cli.sim import modal
from vehid_cli.sim.linear import simulate, simulate_columns

ROOT = Path(__file__).resolve().parents[1]

FIELDS = ("q", "qd", "qdd", "disp", "acc")


def random_cars(n: int, seed: int = 1) -> dict[str, np.ndarray]:
    """n cars with all 16 parameters drawn in [0.7, 1.3] x the paper's values (the identification's search box)."""
    rng = np.random.default_rng(seed)
    return {k: PAPER_CAR[k] * rng.uniform(0.7, 1.3, n) for k in VEHICLE_PARAMETERS}


def assert_same(fast, ref, tol):
    for field in FIELDS:
        assert rel_rms(getattr(fast, field), getattr(ref, field)) < tol, field


def test_paper_case_batch_agrees_with_reference_integrator():
    """Issue acceptance: 20 candidates, 3000 samples: < 1e-6 relative RMS (it is round-off, so ask for 1e-9)."""
    t = time_grid(3.0, 1e-3)
    mats = assemble(random_cars(20))
    road = paper_road(t)
    fast = simulate(mats, road, 1e-3, "exact")
    ref = simulate(mats, road, 1e-3, "exact-reference")
    assert fast.acc.shape == ref.acc.shape == (20, 3000, 4)
    for i in range(20):
        assert rel_rms(fast.acc[i], ref.acc[i]) < 1e-9
        assert rel_rms(fast.disp[i], ref.disp[i]) < 1e-9
    assert_same(fast, ref, 1e-9)


def test_overdamped_and_ill_conditioned_candidates(monkeypatch):
    """Real eigenvalues (huge damping) mix with complex ones in one batch; ill-conditioned ones use the fallback."""
    t = time_grid(1.0, 1e-3)
    road = paper_road(t) + 0.01
    cars = {**PAPER_CAR, "cf": np.array([2800.0, 4e4, 3e5]), "cr": np.array([3500.0, 5e4, 4e5])}
    mats = assemble(cars)
    lam = np.linalg.eigvals(mats.state_space()[0])
    assert (np.abs(lam.imag) == 0).sum(axis=-1).tolist()[0] == 0 and (lam.imag == 0).any(axis=-1)[2]
    ref = simulate(mats, road, 1e-3, "exact-reference")
    assert_same(simulate(mats, road, 1e-3, "exact"), ref, 1e-9)
    monkeypatch.setattr(modal, "COND_MAX", 0.0)  # every candidate through the state-space fallback
    assert_same(simulate(mats, road, 1e-3, "exact"), ref, 1e-9)


def test_road_per_car_and_batch_shapes():
    t = time_grid(0.8, 1e-3)
    roads = np.stack([paper_road(t), 0.5 * paper_road(t)[:, ::-1], paper_road(t) + 0.02])  # (3, n, 4)
    mats = assemble({**PAPER_CAR, "m": np.array([[1100.0, 1300.0, 1500.0]])})  # batch shape (1, 3)
    fast = simulate(mats, roads, 1e-3, "exact")
    ref = simulate(mats, roads, 1e-3, "exact-reference")
    assert fast.acc.shape == (1, 3, t.size, 4)
    assert_same(fast, ref, 1e-9)
    one = simulate(assemble(PAPER_CAR), roads[1], 1e-3, "exact")
    assert one.acc.shape == (t.size, 4)
    np.testing.assert_allclose(fast.acc[0, 1], simulate(assemble(dict(PAPER_CAR, m=1300.0)), roads[1], 1e-3).acc)
    assert rel_rms(one.acc, fast.acc[0, 1]) < 1e-12


@pytest.mark.parametrize("x", [1e-6 + 2e-6j, -3e-3 + 8e-3j, -9.9e-3, -1.01e-2 + 1e-4j, -0.04 + 0.07j, -0.5 + 2.0j])
def test_phi_functions_match_van_loan_matrix_exponential(x):
    """phi1, phi2 of a complex lam dt = the FOH G1, G2 of its real 2x2 form [[a, -b], [b, a]], from expm."""
    dt = 1e-3
    a, b = x.real / dt, x.imag / dt
    A = np.array([[a, -b], [b, a]])
    n = 2
    big = np.zeros((n + 2, n + 2))
    big[:n, :n] = A * dt
    big[:n, n] = [dt, 0.0]  # input on the real part
    big[n, n + 1] = 1.0
    E = scipy.linalg.expm(big)
    phi1, phi2 = modal._phi12(np.array([x]))
    for column, phi in ((E[:n, n], phi1[0]), (E[:n, n + 1], phi2[0])):
        assert abs(complex(*column) - dt * phi) < 1e-13 * abs(dt * phi), (column, dt * phi)


MIXED_LAYOUT = Layout((
    Sensor("roof", "body_acc", x=0.4, y=-0.3),
    Sensor("boot", "body_disp", x=0.2, y=0.1, origin="corner3"),
    Sensor("hub2", "wheel_acc", corner=2),
    Sensor("hop4", "wheel_disp", corner=4),
    Sensor("pot1", "deflection", corner=1),
    Sensor("pot3", "deflection", corner=3),
))  # fmt: skip


def _split_by_condition(cars: dict[str, np.ndarray], monkeypatch) -> np.ndarray:
    """Set COND_MAX between the candidates' eigenvector conditions so that about half of them take the state-space
    fallback, scattered over the blocks of cars; return which ones do."""
    A = assemble(cars).state_space()[0]
    V = np.linalg.eig(A)[1]
    cond = np.abs(V).sum(axis=-2).max(axis=-1) * np.abs(np.linalg.inv(V)).sum(axis=-2).max(axis=-1)
    monkeypatch.setattr(modal, "COND_MAX", float(np.median(cond)))
    good = modal._kept_modes(A)[-1]
    return ~good


@pytest.mark.parametrize("batch", [1, 20, 100])
def test_fast_paths_agree_with_the_reference_at_any_batch_with_fallback_candidates(batch, monkeypatch):
    """The full response (modal_foh) and the layout's channels alone (simulate_columns) against the NumPy
    reference (a matrix exponential and a loop over time, sim.linear._exact_foh) to round-off, 3000 samples, with
    candidates through the modal recursions and the state-space fallback mixed in one batch (blocks of 8 cars)."""
    t = time_grid(3.0, 1e-3)
    road = paper_road(t) + 0.01
    cars = random_cars(batch, seed=batch)
    fallback = _split_by_condition(cars, monkeypatch)
    if batch > 1:
        assert fallback.any() and not fallback.all()
    mats = assemble(cars)
    points = MIXED_LAYOUT.points(cars)
    ref = simulate(mats, road, 1e-3, "exact-reference", points)
    fast = simulate(mats, road, 1e-3, "exact", points)
    assert fast.acc.shape == (batch, t.size, 4)  # four body points: roof, boot, corners 1 and 3
    for i in range(batch):  # car by car: a car's error does not hide in the batch's RMS
        for field in FIELDS:
            assert rel_rms(getattr(fast, field)[i], getattr(ref, field)[i]) < 1e-9, (i, field)
    columns = simulate_columns(mats, road, 1e-3, MIXED_LAYOUT.column_groups, "exact", points)
    channels = MIXED_LAYOUT.read_columns(columns)
    expected = MIXED_LAYOUT.read(ref)
    for family, values in channels.items():
        assert values.shape == expected[family].shape
        for i in range(batch):
            assert rel_rms(values[i], expected[family][i]) < 1e-9, (family, i)


MIXED_YAML = (
    "layout=[{name: roof, kind: body_acc, x: 0.4, y: -0.3}, {name: boot, kind: body_disp, x: 0.2, y: 0.1, "
    "origin: corner3}, {name: hub2, kind: wheel_acc, corner: 2}, {name: hop4, kind: wheel_disp, corner: 4}, "
    "{name: pot1, kind: deflection, corner: 1}, {name: pot3, kind: deflection, corner: 3}]"
)


@pytest.mark.parametrize("overrides", [[], [MIXED_YAML]], ids=["paper", "mixed"])
def test_the_channels_alone_are_the_full_responses_channels(overrides):
    """Experiment.outputs (the identification's path: only the layout's columns projected) against the channels
    read from the whole response (Experiment.simulate), batch 1, 20 and 100 and one car without a batch axis; the
    same numbers (to the last bit here; asked to round-off, which another BLAS may reach in another order)."""
    cfg = load_config(ROOT / "configs" / "gokdag2015" / "base.yaml", overrides)
    exp = build_experiment(cfg)
    assert exp.layout.channel_names == (MIXED_LAYOUT if overrides else corner_layout()).channel_names
    rng = np.random.default_rng(7)
    base = cfg.vehicle.values()
    batches = [{k: base[k] * rng.uniform(0.7, 1.3, b) for k in ("m", "Ix", "a1", "cf")} for b in (1, 20, 100)]
    for values in [None, *batches]:
        fast = exp.outputs(values)
        full = exp.read(exp.simulate(values))
        assert fast.keys() == full.keys() == set(exp.layout.families)
        for family in fast:
            assert fast[family].shape == full[family].shape
            scale = np.max(np.abs(full[family]))
            np.testing.assert_allclose(fast[family], full[family], rtol=0, atol=1e-13 * scale)


def test_columns_of_the_other_integrators_are_picked_from_the_response():
    t = time_grid(0.5, 1e-3)
    mats = assemble(random_cars(3))
    groups = [[("acc", 1), ("q", 4)], [], [("qd", 0)]]
    got = simulate_columns(mats, paper_road(t), 1e-3, groups, "newmark")
    r = simulate(mats, paper_road(t), 1e-3, "newmark")
    np.testing.assert_array_equal(got[0], np.stack([r.acc[..., 1], r.q[..., 4]], axis=-1))
    assert got[1].shape == (3, t.size, 0)
    np.testing.assert_array_equal(got[2][..., 0], r.qd[..., 0])


def test_long_records_run_fewer_cars_at_once():
    """A block's modal coordinates over the whole record stay within SCRATCH_BYTES (at least one car)."""
    assert modal._block_size(3000, 18) == modal.CARS_PER_BLOCK
    for n in (60_000, 600_000, 10**8):
        size = modal._block_size(n, 18)
        assert size >= 1 and (size == 1 or size * n * 18 * 8 <= modal.SCRATCH_BYTES)


@pytest.mark.parametrize("batch", [1, 3, 20])
def test_time_blocks_give_the_same_numbers(batch, monkeypatch):
    """A record run in time blocks (each started from the state its predecessor stored for its last sample) gives
    the numbers of one block over the whole record, bit for bit, with a road per car and blocks of 2 samples up;
    and a long record's block of coordinates stays within BLOCK_BYTES (a 60 s record's were 10 MB per car)."""
    t = time_grid(2.0, 1e-3)
    cars = random_cars(batch, seed=batch + 40)
    mats = assemble(cars)
    rng = np.random.default_rng(batch)
    roads = [paper_road(t) + 0.01, 0.01 * rng.standard_normal((batch, t.size, 4)).cumsum(axis=1) / 30]
    groups = MIXED_LAYOUT.column_groups
    for road in roads:
        monkeypatch.setattr(modal, "BLOCK_BYTES", 2**40)
        whole = simulate_columns(mats, road, 1e-3, groups, "exact", MIXED_LAYOUT.points(cars))
        for size in (16 * 20 * 8 * 8, 4000, 37_000):  # 2 samples of 8 cars, then a few, then uneven blocks
            monkeypatch.setattr(modal, "BLOCK_BYTES", size)
            got = simulate_columns(mats, road, 1e-3, groups, "exact", MIXED_LAYOUT.points(cars))
            for a, b in zip(got, whole, strict=True):
                np.testing.assert_array_equal(a, b)
    seen = []
    original = modal._modal_recursion
    monkeypatch.setattr(modal, "BLOCK_BYTES", 4 * 2**20)
    monkeypatch.setattr(
        modal, "_modal_recursion", lambda e, g, x0, u, out: (seen.append(out.nbytes), original(e, g, x0, u, out))
    )
    simulate_columns(mats, np.repeat(paper_road(t), 30, axis=0)[:60_000] + 0.01, 1e-3, groups, "exact")
    assert len(seen) > 1 and max(seen) <= modal.BLOCK_BYTES


def _lapack_condition(A: np.ndarray) -> np.ndarray:
    """||V||_1 ||V^-1||_1 (P,) of LAPACK's unit eigenvectors: the condition number the modal path tests."""
    V = np.linalg.eig(A)[1]
    return np.abs(V).sum(axis=-2).max(axis=-1) * np.abs(np.linalg.inv(V)).sum(axis=-2).max(axis=-1)


def _second_order_systems() -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(M, C, K) batches: 20 cars of the search box with an overdamped one (real eigenvalues), and 6 random
    non-symmetric 3-DOF systems (the left null vectors by their own solve)."""
    cars = random_cars(20, seed=3)
    cars["cf"][4] = 3e5  # overdamped front: real eigenvalues among complex ones
    car = assemble(cars)
    rng = np.random.default_rng(11)
    d = 3
    M = np.eye(d) + 0.1 * rng.normal(size=(6, d, d))
    C = 0.5 * np.eye(d) + 0.2 * rng.normal(size=(6, d, d))
    K = 4.0 * np.eye(d) + rng.normal(size=(6, d, d))
    return [(car.M, car.C, car.K), (M, C, K)]


@pytest.mark.parametrize("system", [0, 1], ids=["cars", "non-symmetric"])
def test_second_order_modes_are_eigenvectors_and_the_rows_of_their_inverse(system):
    """_second_order_modes (A's eigenvalues by the compiled QR iteration, vectors from the d x d quadratic
    eigenproblem) against the definition: A x = lam x and y A = lam y to round-off, y_i . x_j = delta_ij over every
    mode (the kept ones and their conjugates), the same eigenvalues as LAPACK's eig (in the QR iteration's order) and
    the same condition number as LAPACK's vectors."""
    M, C, K = _second_order_systems()[system]
    d = M.shape[-1]
    A = np.zeros(M.shape[:-2] + (2 * d, 2 * d))
    A[:, :d, d:] = np.eye(d)
    A[:, d:, :d] = -np.linalg.solve(M, K)
    A[:, d:, d:] = -np.linalg.solve(M, C)
    lam, w, V, W, good = modal._second_order_modes(A, M, C, K)
    lam_ref, _, _, _, good_ref = modal._kept_modes(A)
    assert good.all() and np.array_equal(good, good_ref)
    assert lam.shape == lam_ref.shape and np.array_equal(w == 0, lam.imag < 0)
    for p in range(A.shape[0]):  # each kept eigenvalue LAPACK's nearest, one to one, both backward stable: within
        # round-off of the largest (the overdamped car's slowest mode, |lam| 0.16 beside 6900, differs by 2e-13)
        kept, kept_ref = lam[p][w[p] > 0], lam_ref[p][lam_ref[p].imag >= 0]
        nearest = np.abs(kept[:, None] - kept_ref[None, :]).argmin(axis=1)
        assert sorted(nearest) == list(range(kept_ref.size))
        np.testing.assert_allclose(kept, kept_ref[nearest], rtol=0, atol=1e-14 * np.abs(lam_ref[p]).max())
    norm = np.abs(A).max(axis=(-1, -2))[:, None]  # residuals per mode, relative to |A| |vector| (LAPACK's: 2e-14)
    assert (np.abs(A @ V - V * lam[:, None, :]).max(axis=1) / (norm * np.abs(V).max(axis=1))).max() < 1e-13
    assert (np.abs(W @ A - lam[:, :, None] * W).max(axis=2) / (norm * np.abs(W).max(axis=2))).max() < 1e-13
    for p in range(A.shape[0]):  # every mode: the kept ones and the conjugates of the complex ones
        pair = w[p] == 2
        Vf = np.concatenate([V[p][:, w[p] > 0], V[p][:, pair].conj()], axis=1)
        Wf = np.concatenate([W[p][w[p] > 0], W[p][pair].conj()], axis=0)
        assert Vf.shape == (2 * d, 2 * d)
        np.testing.assert_allclose(Wf @ Vf, np.eye(2 * d), atol=1e-11)
        np.testing.assert_allclose(np.linalg.norm(Vf, axis=0), 1.0, rtol=1e-14)
    cond = modal._quadratic_modes(A, M, C, K)[-1]
    np.testing.assert_allclose(cond, _lapack_condition(A), rtol=1e-6)


def test_a_defective_mode_falls_back():
    """A critically damped oscillator (lam = -1 twice, one eigenvector): no inverse to its modes, so the candidate
    goes through the state-space recursion (good False), and one beside it does not."""
    M = np.ones((2, 1, 1))
    K = np.ones((2, 1, 1))
    C = np.array([[[2.0]], [[0.5]]])
    A = np.zeros((2, 2, 2))
    A[:, 0, 1] = 1.0
    A[:, 1, 0] = -K[:, 0, 0]
    A[:, 1, 1] = -C[:, 0, 0]
    good = modal._second_order_modes(A, M, C, K)[-1]
    assert good.tolist() == [False, True]


@pytest.mark.parametrize("K", [1, 6, 50])
def test_propagate_is_the_state_recursion(K):
    """The compiled free recursion s[k + 1] += Phi s[k] over K input histories at once is NumPy's sample-by-sample
    loop to round-off (a stable Phi: the states stay of order one over 3000 samples)."""
    rng = np.random.default_rng(K)
    Q, _ = np.linalg.qr(rng.standard_normal((14, 14)))
    Phi = 0.98 * Q  # spectral radius 0.98
    s = rng.standard_normal((3000, 14, K))
    expected = s.copy()
    for k in range(2999):
        expected[k + 1] += Phi @ expected[k]
    modal.propagate(Phi, s)
    np.testing.assert_allclose(s, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
