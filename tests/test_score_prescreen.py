"""The score statistic that spares a later round the fits of known parameters that cannot be accepted
(attribution.score_statistics, loop._Augmentation.prescreen) against the likelihood ratio of the fit it stands in for
(the independent truth: the candidate fitted by least squares from the same point)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from vehid_cli.config import load_config
from vehid_cli.diagnose.attribution import lsq_fit, score_statistics
from vehid_cli.identify.task import build_task
from vehid_cli.systems.vehicle.diagnosis import prepare_config

BASE = Path(__file__).resolve().parents[1] / "configs" / "gokdag2015" / "base.yaml"
NOISE = ["identify.objective=wls", "noise.level=0.03", "identify.truth=config"]


@pytest.mark.parametrize("factor", [1.01, 1.0])  # the data's front spring 1 % and 0 % off the configured one
def test_score_statistic_equals_the_fitted_likelihood_ratio(factor):
    kf = factor * load_config(BASE).vehicle.kf
    truth = build_task(prepare_config(load_config(BASE, [*NOISE, f"vehicle.kf={kf}"])))
    task = dataclasses.replace(build_task(prepare_config(load_config(BASE, NOISE))), sigma=truth.sigma)
    ref = truth.reference(0)
    declared = lsq_fit(task.problem(ref), task.nominal, 400)
    augmented = task.with_unknowns(["kf"])
    problem = augmented.problem(ref)
    D = task.dim
    x = np.concatenate([declared.x, augmented.nominal[D:]])  # kf at its configured value: the null
    free = np.array([True] * D + [False])
    (S,) = score_statistics(problem, x, free, [D])
    R = problem.residuals(x[None, :])[1].shape[1]
    with_kf = lsq_fit(problem, x, 400)
    LR = max(0.0, (declared.J - with_kf.J) * R)
    assert abs(S - LR) <= 0.05 * LR + 1.0, (S, LR)
    if factor != 1.0:
        assert LR > 20.0  # the case tests something: a mis-set spring the test detects
