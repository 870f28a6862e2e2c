"""The fast exact path (modal recursions) against the NumPy reference of the same discretisation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from tests.conftest import PAPER_CAR
from tests.reference import rel_rms
from tests.test_linear import paper_road
from vehid_cli.io.measurement import time_grid
from vehid_cli.models.fullcar import VEHICLE_PARAMETERS, assemble
from vehid_cli.sim import modal
from vehid_cli.sim.linear import simulate

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
