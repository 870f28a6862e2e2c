"""A long record's normal equations summed block by block (issue 26, optimizers/normal.py): the per-channel sums
against the whole record's arrays (the closed form), the rig's J'J, J'r and Fisher information against the (R, D)
Jacobian they replace, and the fit they drive against the fit on the Jacobian."""

from __future__ import annotations

import numpy as np
import pytest

from examples.make_rig_runs import write_rig_run
from tests.conftest import ROOT
from vehid_cli.config import load_config
from vehid_cli.identify.crlb import information, summed_information
from vehid_cli.optimizers import lsq
from vehid_cli.optimizers.normal import Gram
from vehid_cli.systems import build_system

RIG = ROOT / "configs" / "examples" / "four_post_rig.yaml"


def whole_record_sums(V: np.ndarray, mask: np.ndarray, centred: bool) -> np.ndarray:
    """The truth: each channel's observed rows, centred on their mean over the whole record (two passes), summed."""
    out = np.zeros((V.shape[1], V.shape[2], V.shape[2]))
    for c in range(V.shape[1]):
        rows = V[mask[:, c], c]
        if centred:
            rows = rows - rows.mean(axis=0)
        out[c] = rows.T @ rows
    return out


@pytest.mark.parametrize("centred", [False, True])
@pytest.mark.parametrize("block", [1, 7, 250, 1000])
def test_gram_is_the_whole_records_sums_whatever_the_block(centred, block):
    """Blocks of any size (one row, blocks with channels unobserved throughout, one block) give the whole record's
    sums; centred, a mean 1e4 times the spread (a sensor offset) costs no precision."""
    rng = np.random.default_rng(4)
    n, k, w = 1000, 3, 4
    V = rng.standard_normal((n, k, w)) + 1e4 * rng.standard_normal((1, k, w))
    mask = rng.random((n, k)) < 0.7
    mask[:400, 2] = False  # a channel observed only late: its first blocks hold none of its rows
    gram = Gram(k, w, centred)
    for k0 in range(0, n, block):
        gram.add(V[k0 : k0 + block], mask[k0 : k0 + block])
    truth = whole_record_sums(V, mask, centred)
    scale = np.sqrt(np.einsum("cii,cjj->cij", truth, truth))
    assert np.max(np.abs(gram.sums - truth) / scale) < 1e-11
    np.testing.assert_allclose(gram.total(), truth.sum(axis=0), rtol=1e-11 if not centred else 1e-9)
    full = Gram(k, w, centred)
    full.add(V)  # no mask: every row
    assert np.max(np.abs(full.sums - whole_record_sums(V, np.ones((n, k), bool), centred)) / scale) < 1e-8


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    run = write_rig_run(RIG, tmp_path_factory.mktemp("normal") / "run.mf4", 7, ["simulation.duration=3"])
    return build_system(load_config(RIG, ["simulation.duration=3", "identify.truth=config"]), run)


def test_the_rigs_normal_equations_are_its_jacobians(rig):
    """The measured rig (a slow potentiometer's samples, offsets profiled): J'J and J'r summed block by block are
    those of the residual_jacobian and residuals of the same point to round-off, and so is the Fisher information."""
    task = rig.task
    assert task.offsets and task.observed is not None
    ref = task.reference(0)
    objective = task.objective(ref)
    x = task.truth * np.linspace(0.98, 1.02, task.truth.size)
    out, sens = task.experiment.exact_sensitivities(task.names, x)
    J = objective.residual_jacobian(sens)
    r = objective.residuals({f: v[None] for f, v in out.items()})[0]
    sums = objective.normal_sums(x.size)
    streamed_out, none = task.experiment.exact_sensitivities(task.names, x, sink=sums)
    assert none == {}
    for family in out:
        np.testing.assert_array_equal(streamed_out[family], out[family])
    H, g = sums.result()
    scale = np.sqrt(np.outer(np.diag(J.T @ J), np.diag(J.T @ J)))
    assert np.max(np.abs(H - J.T @ J) / scale) < 1e-12
    assert np.max(np.abs(g - J.T @ r)) < 1e-11 * np.sqrt(np.diag(J.T @ J) * (r @ r)).max()
    F = information(task.experiment, task.names, x, task.sigma, task.observed, task.offsets)
    F_summed = summed_information(task.experiment, task.names, x, task.sigma, task.observed, task.offsets)
    assert np.max(np.abs(F_summed - F) / np.sqrt(np.outer(np.diag(F), np.diag(F)))) < 1e-12


def test_a_fit_on_the_summed_normal_equations_is_the_fit_on_the_jacobian(rig, monkeypatch):
    """The rig identified with its normal equations summed (the threshold of a long record set to zero) and with its
    Jacobian: the same estimate and chi² to round-off, the same number of evaluations."""
    monkeypatch.setattr(lsq, "LONG_JACOBIAN_BYTES", 2**62)
    problem = rig.problem(rig.reference(0))
    assert problem.linearised is not None and problem.normal is None
    full = rig.identify_run(0)
    monkeypatch.setattr(lsq, "LONG_JACOBIAN_BYTES", 0)
    problem = rig.problem(rig.reference(0))
    assert problem.linearised is None and problem.normal is not None
    summed = rig.identify_run(0)
    assert summed.evaluations == full.evaluations
    np.testing.assert_allclose(summed.estimate, full.estimate, rtol=1e-10)
    np.testing.assert_allclose(summed.chi2, full.chi2, rtol=1e-12)
