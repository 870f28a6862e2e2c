"""Close the loop for the full car (`vehid diagnose` on a vehicle config): the declared model fitted by wls on one
measured run or several jointly, candidates from the effect library and the configured known parameters, the
strut force the library cannot explain, held-out blocks (or a --validate run) for the validation J; the loop
itself is `diagnose.loop.close`."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...config import Config, config_from_dict
from ...diagnose.attribution import (
    ALPHA,
    CANDIDATE_BUDGET,
    Z95,
    Fit,
    candidate_ranges,
    candidate_specs,
    chi2_statistic,
    fit_intervals,
    lsq_fit,
)
from ...diagnose.loop import (
    HOLDOUT_EVERY,
    MAX_ROUNDS,
    REFIT_BUDGET,
    Diagnosis,
    ModelReport,
    Subject,
    block_size,
    chi2_limit,
    close,
    holdout_blocks,
    masked,
)
from ...diagnose.quality import assess_vehicle, precheck_vehicle
from ...diagnose.residuals import ResidualAnalysis, analyse
from ...diagnose.shapes import candidate_order
from ...diagnose.unexplained import estimate_unexplained
from ...identify.experiment import run_streams
from ...identify.source import as_paths
from ...identify.task import JointTask, Task, build_task, build_tasks
from ...optimizers import get_optimizer
from ...optimizers.base import Problem


def prepare_config(config: Config) -> Config:
    """The config the diagnosis runs on: wls objective, a time-stepping integrator (effects need one)."""
    raw = config.model_dump(mode="json", exclude_none=True)
    raw["identify"]["objective"] = "wls"
    if raw["simulation"].get("integrator") not in ("rk4", "newmark"):
        raw["simulation"]["integrator"] = "rk4"
    return config_from_dict(raw, config.source)


def holdout_mask(task: Task | JointTask, reference) -> NDArray:
    """(R,) True on the residual entries of held-out samples (holdout_blocks of each run), in the objective's
    residual layout (per run: per family, time-major, observed entries only)."""
    tasks = task.tasks if isinstance(task, JointTask) else (task,)
    refs = reference if isinstance(task, JointTask) else (reference,)
    return np.concatenate(
        [holdout_blocks(t.experiment.t.size)[t.objective(r).sample_times()] for t, r in zip(tasks, refs, strict=True)]
    )


def diagnose(
    config: Config,
    data_file: str | Path | Sequence[str | Path],
    validate_file: str | Path | None = None,
    *,
    alpha: float = ALPHA,
    max_rounds: int = MAX_ROUNDS,
    candidate_budget: int = CANDIDATE_BUDGET,
    refit_budget: int = REFIT_BUDGET,
    analyse_residuals: bool = True,
    log=None,
) -> Diagnosis:
    """Close the loop on the measured run `data_file`, or on several runs jointly (one parameter set; each run its
    own road, noise and offsets; J the wls over every run's residuals, the residual analysis per run); see the
    module doc."""
    t_start = time.perf_counter()
    say = log or (lambda _msg: None)
    config = prepare_config(config)
    files = as_paths(data_file)
    task = build_tasks(config, files)
    joint = isinstance(task, JointTask)
    names_of = " + ".join(str(f) for f in files)
    ref = task.reference(0)
    R_total = task.residual_samples
    if validate_file is not None:
        vtask = build_task(config, validate_file)
        vref = vtask.reference(0)
        keep = vkeep = None
        vsource = f"--validate {validate_file}"
    else:
        vtask, vref = task, ref
        held = holdout_mask(task, ref)
        keep, vkeep = ~held, held
        runs = task.tasks if joint else (task,)
        sizes = sorted({block_size(t.experiment.t.size) for t in runs})
        vsource = (
            f"held-out blocks of {names_of} (every {HOLDOUT_EVERY}th block of {' or '.join(map(str, sizes))} samples)"
        )
    R_train = int(R_total if keep is None else keep.sum())

    def problem_of(t: Task | JointTask, reference, mask) -> Problem:
        return masked(t.problem(reference), mask)

    def augmented(t, names: tuple[str, ...], extra_task: dict):
        """`t` with the unknowns `names` (the task's own first), their ranges from the candidates' specs."""
        extra = [n for n in names if n not in t.names]
        return t.with_unknowns(extra, limits=extra_task["limits"], start=extra_task["start"]) if extra else t

    specs = candidate_specs(config)
    declared = set(config.vehicle.effect_values())
    limits, starts = candidate_ranges(specs)
    ranges = {"limits": limits, "start": starts}

    def validation_J(names: tuple[str, ...], x: NDArray) -> tuple[float, None]:
        vt = augmented(vtask, names, ranges)
        cost = problem_of(vt, vref, vkeep).cost(np.asarray(x, dtype=float)[None, :])[0]
        return (float(cost) if np.isfinite(cost) else float("inf")), None

    def problem_for(names: tuple[str, ...]) -> tuple[Problem, NDArray]:
        t = augmented(task, names, ranges)
        return problem_of(t, ref, keep), t.nominal

    # 0. can the data tell at all? (before any fit: length, noise, excitation)
    pre = precheck_vehicle(task, ref)
    # 1. the declared model, by the configured algorithm (the campaign's run 0 streams), then polished
    ident = config.identify
    base_problem = problem_of(task, ref, keep)
    if pre.ok:
        opt = get_optimizer(ident.algorithm.name, ident.algorithm.population, ident.algorithm.iterations)
        x0 = task.nominal if ident.start == "nominal" else None
        res = opt.minimize(base_problem, run_streams(ident.seed, 0).optimizer, budget=ident.budget, x0=x0)
        fit = lsq_fit(base_problem, res.x, refit_budget)  # polish to the likelihood's minimum
        evaluations = res.evaluations + fit.evaluations
    else:  # no claim will be made: a local fit from the configured values is enough for the record
        fit = lsq_fit(base_problem, task.nominal, refit_budget)
        evaluations = fit.evaluations
    say(f"declared model: J = {fit.J:.4g} ({evaluations} evaluations)")

    def analyses(t, f: Fit) -> tuple[tuple[str, ResidualAnalysis], ...]:
        """The residual analysis of each run (its file and its analysis)."""
        if not joint:
            return ((str(files[0]), analyse(t, ref, f.names, f.x)),)
        return tuple((str(file), analyse(tk, r, f.names, f.x)) for file, tk, r in zip(files, t.tasks, ref, strict=True))

    def report(f: Fit, effs) -> ModelReport:
        t = augmented(task, f.names, ranges)
        ci = fit_intervals(problem_of(t, ref, keep), f, f.J)
        nre = bound = None
        if task.truth is not None:  # the NRE of the declared unknowns, and its bound (sd = half-width / 1.96)
            idx = [f.names.index(n) for n in task.names]
            nre = float(np.linalg.norm(100.0 * (f.x[idx] - task.truth) / task.truth))
            bound = float(np.linalg.norm(100.0 * ci[idx] / Z95 / task.truth))
        vJ, _ = validation_J(f.names, f.x)
        per_run = analyses(t, f) if analyse_residuals else ()
        an = per_run[0][1] if per_run else None
        chi2 = f.J if an is None else (joint_chi2([a for _, a in per_run]) if joint else an.chi2_per_sample)
        return ModelReport(tuple(effs), f.names, f.x, ci, f.J, chi2, vJ, nre, an, fixed=f.fixed,
                           nre_bound_percent=bound, run_analyses=per_run if joint else ())  # fmt: skip

    before = report(fit, ())
    quality = assess_vehicle(task, ref, before, pre)
    missing, order = None, ()
    notes: tuple[str, ...] = ()
    if quality.ok:  # the strut force the declared model misses, non-parametrically: which candidates to fit first
        first, first_ref = (task.tasks[0], ref[0]) if joint else (task, ref)
        first_keep = None if keep is None else keep[: first.residual_samples]
        missing = estimate_unexplained(first, first_ref, fit.names, fit.x, keep=first_keep)
        order = tuple(candidate_order(missing, tuple(specs)))
        if joint:
            notes = (f"the unexplained strut force is estimated from the first run ({files[0]}) alone",)
    subject = Subject(
        specs=specs, declared=frozenset(declared), problem_for=problem_for, validation_J=validation_J,
        residual_count=R_train, statistic=lambda _fit: chi2_statistic(R_train), scale=lambda f: f.J,
        noise_limit=chi2_limit(R_train),
    )  # fmt: skip
    return close(
        subject, fit, before, report, quality, alpha=alpha, max_rounds=max_rounds, candidate_budget=candidate_budget,
        refit_budget=refit_budget, say=say, t_start=t_start, order=order, unexplained=missing,
        chi2_residuals=R_total, validation_source=vsource, sigma_source=task.sigma_source,
        validation_from_file=validate_file is not None, data_files=tuple(map(str, files)) if joint else (),
        extra_notes=notes,
    )  # fmt: skip


def joint_chi2(analyses: Sequence[ResidualAnalysis]) -> float:
    """The residual power per sample over several runs' analyses: every run's squared weighted residuals over
    their count (each channel's own samples)."""
    total = sum(float(np.nansum(a.residual**2)) for a in analyses)
    count = sum(int(np.count_nonzero(np.isfinite(a.residual))) for a in analyses)
    return total / max(count, 1)
