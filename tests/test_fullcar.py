"""The full-car matrices against independent truth: the paper's printed entries, closed-form modes, statics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eigh

from tests.conftest import PAPER_CAR
from vehid_cli.config import config_from_dict
from vehid_cli.models.fullcar import assemble, geometry, parameter_batch


def asymmetric_car(**changes):
    car = dict(PAPER_CAR, a1=1.1, a2=1.6, b1=0.7, b2=0.82, mf=38.0, mr=61.0)
    car.update(changes)
    return car


@pytest.mark.parametrize("car", [PAPER_CAR, asymmetric_car()])
def test_matrices_symmetric_and_definite(car):
    mats = assemble(car)
    for X in (mats.M, mats.C, mats.K):
        np.testing.assert_allclose(X, X.T, rtol=0, atol=1e-9 * np.abs(X).max())
    assert np.linalg.eigvalsh(mats.K).min() > 0
    assert np.linalg.eigvalsh(mats.M).min() > 0
    assert np.linalg.eigvalsh(mats.C).min() > -1e-9 * np.abs(mats.C).max()  # dissipation is never negative


def paper_matrices(p):
    """Gökdağ Eq. 2-6 as printed, for a1 = a2 = a and b1 = b2 = b (where the paper's slips cancel)."""
    a, b, w = p["a1"], p["b1"], 2 * p["b1"]
    kf, kr, ktf, ktr, kR, cf, cr = (p[k] for k in ("kf", "kr", "ktf", "ktr", "kR", "cf", "cr"))
    k22 = kR + (kf + kr) * (b**2 + b**2)
    k33 = 2 * (kf * a**2 + kr * a**2)
    k13 = 2 * (a * kr - a * kf)
    k44 = kf + ktf + kR / w**2
    K = np.array([
        [2 * (kf + kr), 0, k13, -kf, -kf, -kr, -kr],
        [0, k22, 0, -b * kf - kR / w, b * kf + kR / w, b * kr, -b * kr],
        [k13, 0, k33, a * kf, a * kf, -a * kr, -a * kr],
        [-kf, -b * kf - kR / w, a * kf, k44, -kR / w**2, 0, 0],
        [-kf, b * kf + kR / w, a * kf, -kR / w**2, k44, 0, 0],
        [-kr, b * kr, -a * kr, 0, 0, kr + ktr, 0],
        [-kr, -b * kr, -a * kr, 0, 0, 0, kr + ktr],
    ])  # fmt: skip
    c13 = 2 * (a * cr - a * cf)
    C = np.array([
        [2 * (cf + cr), 0, c13, -cf, -cf, -cr, -cr],
        [0, (cf + cr) * 2 * b**2, 0, -b * cf, b * cf, b * cr, -b * cr],
        [c13, 0, 2 * (cf * a**2 + cr * a**2), a * cf, a * cf, -a * cr, -a * cr],
        [-cf, -b * cf, a * cf, cf, 0, 0, 0],
        [-cf, b * cf, a * cf, 0, cf, 0, 0],
        [-cr, b * cr, -a * cr, 0, 0, cr, 0],
        [-cr, -b * cr, -a * cr, 0, 0, 0, cr],
    ])  # fmt: skip
    M = np.diag([p["m"], p["Ix"], p["Iy"], p["mf"], p["mf"], p["mr"], p["mr"]])
    F = np.zeros((7, 4))
    F[3:, :] = np.diag([ktf, ktf, ktr, ktr])
    return M, C, K, F


def test_symmetric_car_matches_paper_printed_entries():
    mats = assemble(PAPER_CAR)
    M, C, K, F = paper_matrices(PAPER_CAR)
    np.testing.assert_allclose(mats.M, M)
    np.testing.assert_allclose(mats.K, K, atol=1e-9)
    np.testing.assert_allclose(mats.C, C, atol=1e-9)
    np.testing.assert_allclose(mats.B, F)


def quarter_car_omegas(ms, mu, ks, kt):
    """Closed-form undamped frequencies of a 2-DOF quarter car [rad/s]."""
    # ms mu w^4 - (ms (ks + kt) + mu ks) w^2 + ks kt = 0
    p = ms * (ks + kt) + mu * ks
    disc = np.sqrt(p**2 - 4 * ms * mu * ks * kt)
    return np.sqrt((p - disc) / (2 * ms * mu)), np.sqrt((p + disc) / (2 * ms * mu))


def test_natural_frequencies_decouple_into_quarter_cars():
    """Symmetric car, no anti-roll bar, Ix = m b², Iy = m a², front = rear: bounce, roll and pitch are each a
    quarter car with sprung mass m/4, Ix/(4b²), Iy/(4a²) = m/4; the warp mode is a wheel on ks + kt alone."""
    a, b, m, mu, ks, kt = 1.2, 0.8, 1200.0, 45.0, 30000.0, 210000.0
    car = dict(m=m, mf=mu, mr=mu, Ix=m * b**2, Iy=m * a**2, a1=a, a2=a, b1=b, b2=b,
               kf=ks, kr=ks, ktf=kt, ktr=kt, kR=0.0, cf=1000.0, cr=1000.0)  # fmt: skip
    mats = assemble(car)
    omega2 = eigh(mats.K, mats.M, eigvals_only=True)
    lo, hi = quarter_car_omegas(m / 4, mu, ks, kt)
    expected = np.sort([lo**2] * 3 + [hi**2] * 3 + [(ks + kt) / mu])
    np.testing.assert_allclose(np.sort(omega2), expected, rtol=1e-10)
    np.testing.assert_allclose(mats.natural_frequencies() ** 2, expected, rtol=1e-10)


def test_anti_roll_bar_only_stiffens_roll():
    """Adding kR raises the roll-mode frequency and leaves the pure bounce mode unchanged."""
    base = assemble(dict(PAPER_CAR, kR=0.0))
    with_bar = assemble(PAPER_CAR)
    bounce = np.array([1, 0, 0, 1, 1, 1, 1.0])
    np.testing.assert_allclose(base.K @ bounce, with_bar.K @ bounce)
    assert np.all(with_bar.natural_frequencies() >= base.natural_frequencies() - 1e-9)


@pytest.mark.parametrize("car", [PAPER_CAR, asymmetric_car()])
def test_constant_road_lift_is_a_rigid_lift(car):
    mats = assemble(car)
    h = 0.037
    q = np.linalg.solve(mats.K, mats.B @ np.full(4, h))
    np.testing.assert_allclose(q, [h, 0, 0, h, h, h, h], atol=1e-13)


def test_geometry_is_eq7():
    G = geometry(1.1, 1.5, 0.7, 0.8)
    x, phi, theta = 0.01, 0.02, -0.03
    z = G @ [x, phi, theta]
    np.testing.assert_allclose(
        z,
        [
            x + 0.7 * phi - 1.1 * theta,
            x - 0.8 * phi - 1.1 * theta,
            x - 0.8 * phi + 1.5 * theta,
            x + 0.7 * phi + 1.5 * theta,
        ],
    )


def test_batch_assembly_equals_one_at_a_time():
    rng = np.random.default_rng(1)
    cars = [asymmetric_car(m=1300 * f, a1=1.3 * g) for f, g in rng.uniform(0.7, 1.3, size=(5, 2))]
    batch = {k: np.array([c[k] for c in cars]) for k in cars[0]}
    mats = assemble(batch)
    for i, car in enumerate(cars):
        single = assemble(car)
        np.testing.assert_allclose(mats.K[i], single.K)
        np.testing.assert_allclose(mats.C[i], single.C)
        np.testing.assert_allclose(mats.M[i], single.M)


def test_parameter_batch_keeps_wheelbase_and_track():
    cfg = config_from_dict({"vehicle": PAPER_CAR, "road": {"speed_kmh": 20, "bump": {"heights": [0.05] * 4}}})
    p = parameter_batch(cfg.vehicle, {"a1": np.array([1.0, 1.5]), "b1": np.array([0.6, 0.9])})
    np.testing.assert_allclose(p["a1"] + p["a2"], 2.6)
    np.testing.assert_allclose(p["b1"] + p["b2"], 1.5)
    np.testing.assert_allclose(p["m"], [1300, 1300])
