"""sim/expm.py: the matrix exponential against closed forms (diagonal, rotation, nilpotent, a commuting sum), against
a long-double Taylor series on the cars' Van Loan matrices (as accurate as scipy.linalg.expm there) and against
scipy's on random stacks, to round-off (each squaring may double a relative error: 2^s in the tolerances)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from tests.conftest import ROOT
from vehid_cli.config import load_config
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.sim.expm import expm


@pytest.mark.parametrize("scale", [1e-6, 0.3, 5.0, 80.0])
def test_closed_forms(scale):
    d = np.array([-1.0, 0.5, 2.0]) * scale
    squarings = max(0.0, np.ceil(np.log2(2 * scale / 5.37)))
    np.testing.assert_allclose(expm(np.diag(d)), np.diag(np.exp(d)), rtol=1e-14 * 2**squarings, atol=0)
    w = scale
    rotation = expm(np.array([[0.0, -w], [w, 0.0]]))
    np.testing.assert_allclose(rotation, [[np.cos(w), -np.sin(w)], [np.sin(w), np.cos(w)]], atol=1e-14 * max(1, w))
    N = np.diag([scale, scale, scale], k=1)  # nilpotent: the series stops after N^3
    np.testing.assert_allclose(expm(N), np.eye(4) + N + N @ N / 2 + N @ N @ N / 6, rtol=1e-14, atol=1e-300)
    a, b = -0.4 * scale, 0.7 * scale  # a I + b J with J a rotation generator: e^a times a rotation by b
    M = np.array([[a, -b], [b, a]])
    expected = np.exp(a) * np.array([[np.cos(b), -np.sin(b)], [np.sin(b), np.cos(b)]])
    np.testing.assert_allclose(expm(M), expected, rtol=1e-13, atol=1e-14 * np.abs(expected).max())


def long_double_exponential(A: np.ndarray) -> np.ndarray:
    """exp(A) by 25 Taylor terms of A / 2^s (norm <= 0.01) squared s times, in long double (x86: 64-bit mantissa)."""
    A = A.astype(np.longdouble)
    s = max(0, int(np.ceil(np.log2(float(np.abs(A).sum(axis=0).max()) / 0.01))))
    X = A / np.longdouble(2) ** s
    E = term = np.eye(A.shape[0], dtype=np.longdouble)
    for k in range(1, 25):
        term = term @ X / k
        E = E + term
    for _ in range(s):
        E = E @ E
    return E


@pytest.mark.skipif(np.finfo(np.longdouble).eps > 1e-18, reason="long double is double here: no reference")
def test_the_cars_van_loan_matrices_to_round_off():
    """The 22 x 22 matrices of the exact FOH of cars around the paper's (a large input block over the stable states:
    far from normal), at 1 ms and at 50 ms, each with its own scaling: within 1e-14 of their largest entry, as
    scipy's (2.6e-15-3.8e-15 at 50 ms; ours 2.4e-15-4.4e-15; it was 1e-12 when scaled by ||A|| alone)."""
    exp = build_experiment(load_config(ROOT / "configs" / "gokdag2015" / "base.yaml"))
    rng = np.random.default_rng(0)
    base = exp.config.vehicle.values()
    values = {k: base[k] * rng.uniform(0.5, 1.5, 6) for k in exp.config.identify.unknowns}
    A, Bs = exp.matrices(values).state_space()
    for dt in (1e-3, 5e-2):
        n, m = A.shape[-1], Bs.shape[-1]
        big = np.zeros(A.shape[:-2] + (n + 2 * m, n + 2 * m))
        big[..., :n, :n], big[..., :n, n : n + m], big[..., n : n + m, n + m :] = A * dt, Bs * dt, np.eye(m)
        ours = expm(big)
        for i in range(big.shape[0]):
            ref = long_double_exponential(big[i])
            assert float(np.abs(ours[i] - ref).max()) <= 1e-14 * float(np.abs(ref).max())
            assert np.abs(ours[i] - scipy.linalg.expm(big[i])).max() <= 2e-14 * np.abs(ours[i]).max()


def test_random_stacks_of_every_scale_as_scipys():
    rng = np.random.default_rng(1)
    for n in (1, 3, 8):
        A = rng.standard_normal((5, n, n)) * np.array([1e-3, 0.1, 1.0, 10.0, 40.0])[:, None, None]
        ours = expm(A)
        for i in range(5):
            ref = scipy.linalg.expm(A[i])
            np.testing.assert_allclose(ours[i], ref, rtol=1e-11, atol=1e-12 * np.abs(ref).max())


def test_bad_input():
    with pytest.raises(ValueError, match="square"):
        expm(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="infs or NaNs"):
        expm(np.array([[np.nan]]))
