"""The integrators against independent references: adaptive DOP853, scipy.signal.lsim, conservation, order."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from tests.conftest import PAPER_CAR
from tests.reference import reference_response, rel_rms
from vehid_cli.config import Bump
from vehid_cli.io.measurement import time_grid
from vehid_cli.models.fullcar import assemble
from vehid_cli.models.road import bump_road
from vehid_cli.sim.linear import foh_discretisation, simulate

V = 20 / 3.6
L = 2.6
PAPER_BUMP = Bump(shape="cosine_step", length=0.1, heights=(0.05, 0.04, 0.04, 0.05), start_time=0.1)


def paper_road(t):
    return bump_road(PAPER_BUMP, V, L, t)


@pytest.fixture(scope="module")
def paper_reference():
    t = time_grid(3.0, 1e-3)
    return t, reference_response(assemble(PAPER_CAR), paper_road, t)


@pytest.mark.parametrize("integrator", ["exact", "newmark"])
def test_paper_case_agrees_with_converged_reference(paper_reference, integrator):
    """Issue acceptance: relative RMS error of the accelerations < 1e-3 at dt = 1 ms (displacements too)."""
    t, (disp_ref, acc_ref) = paper_reference
    r = simulate(assemble(PAPER_CAR), paper_road(t), 1e-3, integrator)
    assert rel_rms(r.acc, acc_ref) < 1e-3
    assert rel_rms(r.disp, disp_ref) < 1e-3


def test_exact_matches_lsim_to_roundoff():
    """scipy.signal.lsim interpolates the input linearly too: the same system must give the same answer."""
    car = dict(PAPER_CAR, a1=1.2, a2=1.4, b1=0.7, b2=0.8)
    mats = assemble(car)
    t = time_grid(2.0, 1e-3)
    road = paper_road(t) + 0.004 * np.sin(2 * np.pi * 3.0 * t)[:, None]
    r = simulate(mats, road, 1e-3, "exact")
    A, Bs = mats.state_space()
    Cd = np.zeros((4, 14))
    Cd[:, :3] = mats.G
    _, y, _ = signal.lsim((A, Bs, Cd, np.zeros((4, 4))), road, t)
    assert rel_rms(r.disp, y) < 1e-9


def test_foh_discretisation_of_scalar_system():
    """x' = -a x + u with u linear over the step has a closed-form update."""
    a, dt = 3.0, 0.1
    Phi, G1, G2 = foh_discretisation(np.array([[-a]]), np.array([[1.0]]), dt)
    e = np.exp(-a * dt)
    np.testing.assert_allclose(Phi, [[e]])
    np.testing.assert_allclose(G1, [[(1 - e) / a]])
    np.testing.assert_allclose(G2, [[(dt - (1 - e) / a) / (a * dt)]])


def smooth_road(t):
    """Gaussian bumps (infinitely smooth), rear delayed: the integrators, not kinks in the road, set the error."""
    t = np.asarray(t, dtype=float)[:, None]
    delay = np.array([0.0, 0.0, 0.25, 0.25])
    heights = np.array([0.05, 0.03, 0.03, 0.05])
    return heights * np.exp(-(((t - 0.3 - delay) / 0.04) ** 2))


@pytest.mark.parametrize("integrator", ["exact", "newmark"])
def test_dt_halving_shows_second_order(integrator):
    """Both schemes are second order (Newmark: average acceleration; exact: the hold on the road)."""
    mats = assemble(PAPER_CAR)
    t_fine = time_grid(1.5, 1e-3)
    _, acc_ref = reference_response(mats, smooth_road, t_fine)
    errors = []
    for stride in (8, 4, 2):
        dt = stride * 1e-3
        t = t_fine[::stride]
        r = simulate(mats, smooth_road(t), dt, integrator)
        errors.append(rel_rms(r.acc, acc_ref[::stride]))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 1.8) & (orders < 2.3)), (errors, orders)


def test_undamped_car_conserves_energy_after_the_road_stops_changing():
    car = dict(PAPER_CAR, cf=0.0, cr=0.0, a1=1.2, a2=1.4)
    mats = assemble(car)
    t = time_grid(4.0, 1e-3)
    road = paper_road(t)
    q_end = np.linalg.solve(mats.K, mats.B @ road[-1])
    r = simulate(mats, road, 1e-3, "exact")
    after = t > 0.1 + 2.6 / V + 0.05  # both axles are over the ramp
    dq = r.q[after] - q_end
    energy = 0.5 * np.einsum("ni,ij,nj->n", r.qd[after], mats.M, r.qd[after]) + 0.5 * np.einsum(
        "ni,ij,nj->n", dq, mats.K, dq
    )
    assert energy.max() > 0
    assert (energy.max() - energy.min()) / energy.mean() < 1e-8


def test_damped_car_settles_to_the_rigid_lift():
    mats = assemble(PAPER_CAR)
    t = time_grid(12.0, 2e-3)
    bump = Bump(shape="cosine_step", length=0.1, heights=(0.03,) * 4, start_time=0.1)
    r = simulate(mats, bump_road(bump, V, L, t), 2e-3, "exact")
    np.testing.assert_allclose(r.q[-1], [0.03, 0, 0, 0.03, 0.03, 0.03, 0.03], atol=1e-6)


def test_batch_equals_one_at_a_time():
    t = time_grid(1.0, 1e-3)
    road = paper_road(t)
    masses = np.array([1000.0, 1300.0, 1600.0])
    batch = assemble({**PAPER_CAR, "m": masses})
    for integrator in ("exact", "newmark"):
        rb = simulate(batch, road, 1e-3, integrator)
        for i, m in enumerate(masses):
            r1 = simulate(assemble(dict(PAPER_CAR, m=m)), road, 1e-3, integrator)
            np.testing.assert_allclose(rb.acc[i], r1.acc, rtol=1e-10, atol=1e-12)


def test_starts_in_equilibrium_on_a_raised_road():
    """A road that starts raised: the car starts at rest on it, so a constant road means no motion at all."""
    mats = assemble(PAPER_CAR)
    road = np.full((500, 4), 0.02)
    for integrator in ("exact", "newmark"):
        r = simulate(mats, road, 1e-3, integrator)
        np.testing.assert_allclose(r.acc, 0.0, atol=1e-10)
        np.testing.assert_allclose(r.disp, 0.02, atol=1e-12)
