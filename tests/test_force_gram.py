"""The missing force's fit on a long window without its fit matrix A (diagnose/linear_response.response_gram and
ForceFit from the normal equations): the same sums and statistics as from A, to round-off."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_unexplained import damping, force_inputs  # noqa: F401  (damping: a fixture)
from vehid_cli.diagnose.linear_response import ForceFit, response_columns, response_gram
from vehid_cli.diagnose.psplines import penalised_fit


@pytest.mark.parametrize("offsets", [False, True])
def test_the_fit_matrix_sums_equal_the_held_ones(damping, offsets):  # noqa: F811
    """response_gram's A'A and A'r equal those of response_columns' A = [J | S[keep]] to 1e-12 of each entry's scale
    (summed block by block without offsets, from A with them); the fit's RSS and each curve's explained share from
    them equal the ones from A to 1e-10."""
    task, objective, car, U, rng = force_inputs(damping, offsets, seed=5)
    keep = rng.random(objective.size) < 0.7
    J = rng.standard_normal((int(keep.sum()), 3))
    r = rng.standard_normal(int(keep.sum())) + J @ np.array([0.5, -1.0, 2.0])
    A = response_columns(objective, car, U, task.sigma, keep, 3)
    A[:, :3] = J
    G, g = response_gram(objective, car, U, task.sigma, keep, J, r)
    d = np.sqrt(np.diag(A.T @ A))
    assert np.max(np.abs(G - A.T @ A) / np.outer(d, d)) < 1e-12
    assert np.max(np.abs(g - A.T @ r) / (d * np.linalg.norm(r))) < 1e-12
    sol = penalised_fit(A.T @ A, A.T @ r, float(r @ r), r.size, [(slice(3, 9), np.eye(6))])
    held = ForceFit(None, None, (), U, A, A.T @ A, A.T @ r, r, sol, 3)
    summed = ForceFit(None, None, (), U, None, G, g, r, sol, 3)
    assert summed.rss(sol.coef) == pytest.approx(held.rss(sol.coef), rel=1e-10)
    for sl, line in ((slice(3, 6), None), (slice(6, 9), 1)):
        assert summed.explained(sl, line) == pytest.approx(held.explained(sl, line), rel=1e-10)
        assert held.explained(sl, line) > 0
