"""The compiled eigenvalues (sim.eigenvalues) against matrices whose eigenvalues are known by construction, against
the reciprocals of the inverse's (a stiff car's slow modes) and against LAPACK's."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_modal import random_cars
from vehid_cli.models.fullcar import assemble
from vehid_cli.sim.eigenvalues import eigenvalues


def _matched(got: np.ndarray, want: np.ndarray) -> np.ndarray:
    """`want` reordered to `got`'s order, each to its nearest, one to one (or AssertionError)."""
    nearest = np.abs(got[:, None] - want[None, :]).argmin(axis=1)
    assert sorted(nearest) == list(range(want.size))
    return want[nearest]


@pytest.mark.parametrize("n", [1, 2, 3, 7, 14, 20])
def test_known_eigenvalues_of_a_rotated_block_diagonal(n):
    """Q D Q^T with Q orthogonal and D block diagonal (real eigenvalues and 2 x 2 blocks [[a, b], [-b, a]], a +- i b):
    its eigenvalues to round-off of its norm, each complex pair exactly conjugate, each real one with Im exactly 0."""
    rng = np.random.default_rng(n)
    D = np.zeros((n, n))
    want = []
    i = 0
    while i < n:
        if i + 1 < n and rng.random() < 0.6:
            a, b = rng.normal(), rng.uniform(0.5, 3.0)
            D[i : i + 2, i : i + 2] = [[a, b], [-b, a]]
            want += [complex(a, b), complex(a, -b)]
            i += 2
        else:
            D[i, i] = rng.normal()
            want.append(complex(D[i, i]))
            i += 1
    Q = np.linalg.qr(rng.normal(size=(n, n)))[0]
    lam = eigenvalues((Q @ D @ Q.T)[None])[0]
    np.testing.assert_allclose(lam, _matched(lam, np.array(want)), rtol=0, atol=1e-13 * np.abs(want).max())
    complex_ = lam[lam.imag != 0]
    assert np.all(np.isin(complex_.conj(), complex_))  # exact conjugates
    assert np.sum(lam.imag == 0) == sum(w.imag == 0 for w in want)


def test_a_stiff_cars_slow_modes_to_their_own_precision():
    """Overdamped cars (|lam| from 0.16 to 9000): each slow eigenvalue against 1 / (the largest ones of A^-1), which
    have it to its own relative precision, within 1e-16 of the largest |lam| (a backward-stable solver's round-off is
    eps |A|: LAPACK's errors here are 1e-19 to 3e-17 of it, these 1e-20 to 2e-17)."""
    cars = random_cars(6, seed=3)
    cars["cf"][:] = 3e5
    car = assemble(cars)
    d = car.M.shape[-1]
    for M, C, K in zip(car.M, car.C, car.K, strict=True):
        A = np.block([[np.zeros((d, d)), np.eye(d)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
        A_inv = np.block([[-np.linalg.solve(K, C), -np.linalg.solve(K, M)], [np.eye(d), np.zeros((d, d))]])
        lam = eigenvalues(A[None])[0]
        slow = 1.0 / np.linalg.eigvals(A_inv)
        slow = slow[np.abs(slow) < 1.0]
        assert slow.size >= 1
        for z in slow:
            assert np.abs(lam - z).min() < 1e-16 * np.abs(lam).max()


def test_random_matrices_as_lapack():
    """200 random 14 x 14 matrices and 20 cars of the search box: LAPACK's eigenvalues to round-off of the norm."""
    rng = np.random.default_rng(0)
    car = assemble(random_cars(20, seed=1))
    A_car = np.zeros((20, 14, 14))
    A_car[:, :7, 7:] = np.eye(7)
    A_car[:, 7:, :7] = -np.linalg.solve(car.M, car.K)
    A_car[:, 7:, 7:] = -np.linalg.solve(car.M, car.C)
    for A in (rng.normal(size=(200, 14, 14)), A_car):
        lam, ref = eigenvalues(A), np.linalg.eigvals(A)
        for got, want in zip(lam, ref, strict=True):
            np.testing.assert_allclose(got, _matched(got, want), rtol=0, atol=1e-13 * np.abs(want).max())


def test_a_matrix_that_is_not_finite_gets_lapacks_error():
    """NaN or inf in a matrix: the QR iteration leaves it to LAPACK, which refuses it as before."""
    A = np.eye(3)[None].repeat(2, axis=0)
    A[1, 0, 2] = np.nan
    with pytest.raises(np.linalg.LinAlgError):
        eigenvalues(A)


def test_degenerate_sizes_and_the_zero_matrix():
    """1 x 1 (its entry), the zero matrix (all zero) and an empty batch."""
    np.testing.assert_array_equal(eigenvalues(np.array([[[-2.5]]])), [[-2.5 + 0j]])
    np.testing.assert_array_equal(eigenvalues(np.zeros((1, 4, 4))), np.zeros((1, 4)))
    assert eigenvalues(np.zeros((0, 5, 5))).shape == (0, 5)
