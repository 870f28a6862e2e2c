"""Close the loop for the full car (`vehid diagnose` on a vehicle config): the declared model fitted by wls on one
measured run or several jointly, candidates from the effect library and the configured known parameters, the
strut force the library cannot explain, held-out blocks (or a --validate run) for the validation J; the loop
itself is `diagnose.loop.close`."""

from __future__ import annotations

import dataclasses
import functools
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...config import Config, config_from_dict
from ...core.allocator import release_if_handing_back
from ...core.progress import ProgressHook
from ...core.streams import run_streams
from ...diagnose.attribution import (
    ALPHA,
    CANDIDATE_BUDGET,
    SCREEN_TOL,
    Z95,
    Candidate,
    Fit,
    candidate_ranges,
    candidate_specs,
    chi2_statistic,
    fit_intervals,
    lsq_fit,
    misfit_ci,
    sensor_candidates,
)
from ...diagnose.checks import check_runs
from ...diagnose.holdout import HOLDOUT_EVERY, block_size, holdout_blocks, masked
from ...diagnose.loop import MAX_ROUNDS, REFIT_BUDGET, close
from ...diagnose.quality import assess_vehicle, precheck_vehicle
from ...diagnose.residuals import ResidualAnalysis, analyse
from ...diagnose.result import Diagnosis, ModelReport, chi2_limit
from ...diagnose.subject import Subject
from ...diagnose.unexplained import Unexplained, estimate_unexplained
from ...diagnose.window import SCREEN_SAMPLES, is_long, window_task
from ...identify.source import as_paths
from ...identify.task import JointTask, Task, build_task, build_tasks
from ...optimizers import get_optimizer
from ...optimizers.base import Problem, Search
from ...optimizers.lsq import gauss_newton

References = dict[str, NDArray] | tuple[dict[str, NDArray], ...]  # one run's reference data, or each run's


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


@dataclass(frozen=True)
class ValidationSplit:
    """Where the validation J is computed: the --validate run (its task and reference; every training residual
    kept), else held-out blocks of the training data (`keep` the training entries, `held` the held-out ones, in the
    objective's residual layout); `source` says which."""

    task: Task | JointTask
    reference: References
    keep: NDArray | None
    held: NDArray | None
    source: str


def validation_split(
    config: Config, task: Task | JointTask, ref: References, files: Sequence[str], validate_file: str | Path | None
) -> ValidationSplit:
    """The --validate run `validate_file` when given, else every HOLDOUT_EVERY-th block of the training runs."""
    if validate_file is not None:
        vtask = build_task(config, validate_file)
        return ValidationSplit(vtask, vtask.reference(0), None, None, f"--validate {validate_file}")
    held = holdout_mask(task, ref)
    runs = task.tasks if isinstance(task, JointTask) else (task,)
    sizes = sorted({block_size(t.experiment.t.size) for t in runs})
    names_of = " + ".join(str(f) for f in files)
    source = f"held-out blocks of {names_of} (every {HOLDOUT_EVERY}th block of {' or '.join(map(str, sizes))} samples)"
    return ValidationSplit(task, ref, ~held, held, source)


class SinglePoints:
    """The whole residual vectors of the last single-point evaluations of the training problems, by (unknowns, x):
    a fit's last point is one, and its validation J on held-out blocks of the same runs is then read from it instead
    of simulating the car again (the same task, data and point give the same vector). At most MAX_BYTES held; the
    candidates' fits record from several threads."""

    MAX_BYTES = 8 * 2**20  # a 60 s record's vector is 6 MB: one held (the newest is always kept)
    MAX_POINTS = 8  # and at most this many: a window's small vectors, beyond the last points of the fits under way
    # (two threads), were held by the hundred KB for nothing

    def __init__(self) -> None:
        self._store: OrderedDict[tuple, NDArray] = OrderedDict()
        self._lock = threading.Lock()

    def recording(self, problem: Problem, names: tuple[str, ...]) -> Problem:
        """`problem` (its residuals the whole vector) recording each single point it evaluates."""
        inner = problem.residuals

        def residuals(X):
            costs, r = inner(X)
            if np.shape(X)[0] == 1:
                self._put((names, np.asarray(X[0], dtype=float).tobytes()), r[0])
            return costs, r

        return dataclasses.replace(problem, residuals=residuals)

    def _put(self, key: tuple, r: NDArray) -> None:
        with self._lock:
            self._store.pop(key, None)
            self._store[key] = r
            while len(self._store) > 1 and (
                len(self._store) > self.MAX_POINTS or sum(v.nbytes for v in self._store.values()) > self.MAX_BYTES
            ):
                self._store.popitem(last=False)

    def clear(self) -> None:
        """Forget every vector (no fit's validation J will be asked for again)."""
        with self._lock:
            self._store.clear()

    def get(self, names: tuple[str, ...], x: NDArray) -> NDArray | None:
        """The whole residual vector the training problem over `names` computed at x, if still held."""
        with self._lock:
            return self._store.get((tuple(names), np.asarray(x, dtype=float).tobytes()))


@dataclass(frozen=True)
class CarLoop:
    """The car's side of the loop: its training and validation problems over any unknowns (the task's own first,
    the others' ranges from the candidates' specs) and the report of a fit."""

    task: Task | JointTask
    ref: References
    split: ValidationSplit
    ranges: dict  # "limits" and "start" of the candidates' unknowns
    files: tuple[str, ...]
    analyse_residuals: bool = True
    twin: Task | None = None  # the task on the exact integrator when the declared model is the linear car (exact_twin)
    points: SinglePoints = field(default_factory=SinglePoints, repr=False, compare=False)
    measured: dict[int, NDArray] = field(default_factory=dict, repr=False, compare=False)  # run -> its analyses' data

    @property
    def joint(self) -> bool:
        """Several runs fitted jointly (a JointTask)?"""
        return isinstance(self.task, JointTask)

    @staticmethod
    def problem_of(t: Task | JointTask, reference: References, mask: NDArray | None) -> Problem:
        """The wls problem of `t` on `reference`, on the residual entries `mask` keeps."""
        return masked(t.problem(reference), mask)

    def augmented(self, t: Task | JointTask, names: tuple[str, ...]) -> Task | JointTask:
        """`t` with the unknowns `names` (the task's own first), their ranges from the candidates' specs."""
        extra = [n for n in names if n not in t.names]
        return t.with_unknowns(extra, limits=self.ranges["limits"], start=self.ranges["start"]) if extra else t

    def validation_J(self, names: tuple[str, ...], x: NDArray) -> tuple[float, None]:
        """J on the validation data (held-out blocks or the --validate run) at `names` = x."""
        split = self.split
        x = np.asarray(x, dtype=float)
        whole = self.points.get(names, x) if split.held is not None and split.task is self.task else None
        if whole is None:
            vt = self.augmented(split.task, names)
            cost = self.problem_of(vt, split.reference, split.held).cost(x[None, :])[0]
        else:  # the training problem's vector at x: held-out entries taken as masked() takes them
            with np.errstate(all="ignore"):
                cost = np.mean(whole[None, :][:, split.held] ** 2, axis=1)[0]
        return (float(cost) if np.isfinite(cost) else float("inf")), None

    def problem_for(self, names: tuple[str, ...]) -> tuple[Problem, NDArray]:
        """The training problem over `names` and their start values."""
        t = self.augmented(self.task, names)
        problem = t.problem(self.ref)
        if self.split.held is not None and problem.residuals is not None:  # its fits' validation J from their points
            problem = self.points.recording(problem, tuple(names))
        return masked(problem, self.split.keep), t.nominal

    def linear_for(self, names: tuple[str, ...]) -> Problem | None:
        """The training problem over `names` on the exact integrator with its exact sensitivities (`exact_twin`; a
        long record's as normal equations summed over the kept samples), or None where that model is not the linear
        car (an effect's or a sensor's unknowns among `names`)."""
        if self.twin is None or not set(names) <= set(self.twin.config.vehicle.values()):
            return None
        t = self.augmented(self.twin, names)
        if t.corrections or not t.experiment.exact_applies(t.names):
            return None
        problem = self.problem_of(t, self.ref, self.split.keep)
        return problem if problem.linearised is not None or problem.normal is not None else None

    def analyses(self, t: Task | JointTask, f: Fit) -> tuple[tuple[str, ResidualAnalysis], ...]:
        """The residual analysis of each run (its file and its analysis)."""
        runs = list(zip(t.tasks, self.ref, strict=True)) if self.joint else [(t, self.ref)]
        files = self.files if self.joint else self.files[:1]
        out = []
        for i, (file, (tk, r)) in enumerate(zip(files, runs, strict=True)):
            an = analyse(tk, r, f.names, f.x, measured=self.measured.get(i))  # the run's data laid out once, shared
            self.measured.setdefault(i, an.measured)
            out.append((str(file), an))
        return tuple(out)

    def report(self, f: Fit, effs: Sequence[str]) -> ModelReport:
        """The fit `f` with the effects `effs`: intervals, J, validation J, NRE and its bound (truth known), the
        residual analysis."""
        task = self.task
        t = self.augmented(task, f.names)
        problem = self.problem_of(t, self.ref, self.split.keep)
        ci = fit_intervals(problem, f, f.J, None if f.fixed else self.linear_for(f.names))
        kept = task.residual_samples if self.split.keep is None else int(self.split.keep.sum())
        misfit = misfit_ci(problem, f) if f.J > chi2_limit(kept) else None  # the model is wrong: say how wide
        nre = bound = None
        if task.truth is not None:  # the NRE of the declared unknowns, and its bound (sd = half-width / 1.96)
            idx = [f.names.index(n) for n in task.names]
            nre = float(np.linalg.norm(100.0 * (f.x[idx] - task.truth) / task.truth))
            bound = float(np.linalg.norm(100.0 * ci[idx] / Z95 / task.truth))
        vJ, _ = self.validation_J(f.names, f.x)
        per_run = self.analyses(t, f) if self.analyse_residuals else ()
        an = per_run[0][1] if per_run else None
        chi2 = f.J if an is None else (joint_chi2([a for _, a in per_run]) if self.joint else an.chi2_per_sample)
        return ModelReport(tuple(effs), f.names, f.x, ci, f.J, chi2, vJ, nre, an, fixed=f.fixed,
                           nre_bound_percent=bound, run_analyses=per_run if self.joint else (),
                           ci_misfit=misfit)  # fmt: skip


def exact_twin(task: Task | JointTask) -> Task | None:
    """The task on the exact integrator (the linear car's modal solution) when its declared model is the linear car
    of one run (no effects, no measurement-chain corrections, vehicle parameters only): its problem carries the
    exact sensitivities (`Problem.linearised`), with which Levenberg–Marquardt converges in a few evaluations. The
    diagnosis itself stays on its time-stepping integrator (the effects' candidates need one): the twin only gives
    the start of the polish there, which is its minimum up to the integrators' difference (rk4 at dt: ~(w dt)^4)."""
    if isinstance(task, JointTask) or task.corrections or task.experiment.effects():
        return None
    sim = task.config.simulation.model_copy(update={"integrator": "exact"})
    cfg = task.config.model_copy(update={"simulation": sim})
    twin = dataclasses.replace(task, config=cfg, experiment=dataclasses.replace(task.experiment, config=cfg))
    return twin if twin.experiment.exact_applies(task.names) else None


def fit_declared(
    config: Config,
    task: Task | JointTask,
    problem: Problem,
    precheck_ok: bool,
    refit_budget: int,
    say: Callable[[str], None],
    search: Problem | None = None,
    linear: Problem | None = None,
) -> Fit:
    """The declared model, by the configured algorithm (the campaign's run 0 streams) on `search` (a long record's
    screening window; default `problem`), then polished to the likelihood's minimum on `problem`; when the data
    failed the pre-check (no claim will be made) a local fit from the configured values, enough for the record.
    `linear`: the same problem on the exact integrator with its exact sensitivities (`exact_twin`, the linear car; a
    long record's as normal equations summed over its blocks, no Jacobian held): then Levenberg–Marquardt from the
    configured values on it replaces the global search (a few evaluations instead of ~1000; the search only when it
    fails), and the polish on `problem` starts from its minimum and goes to SCREEN_TOL, as a round's re-fits (the
    two integrators' minima are that close: 7 evaluations instead of 24 on a 60 s record; the final model's polish
    goes to 1e-12)."""
    ident = config.identify
    if precheck_ok and linear is not None:
        run = Search(linear, run_streams(ident.seed, 0).optimizer, ident.budget or refit_budget)
        x = gauss_newton(run, task.nominal)
        if x is not None and np.isfinite(run.best_cost):
            fit = lsq_fit(problem, run.best_x, refit_budget, tol=SCREEN_TOL)
            say(f"declared model: J = {fit.J:.4g} ({run.evaluations} exact + {fit.evaluations} evaluations)")
            return fit
    if precheck_ok:
        opt = get_optimizer(ident.algorithm.name, ident.algorithm.population, ident.algorithm.iterations)
        x0 = task.nominal if ident.start == "nominal" else None
        res = opt.minimize(search or problem, run_streams(ident.seed, 0).optimizer, budget=ident.budget, x0=x0)
        start, evaluations = res.x, res.evaluations
        if search is not None:  # polished on the window first: the whole record's polish then starts next to it
            on_window = lsq_fit(search, start, refit_budget)
            start, evaluations = on_window.x, evaluations + on_window.evaluations
        fit = lsq_fit(problem, start, refit_budget)  # polish to the likelihood's minimum
        evaluations += fit.evaluations
    else:  # no claim will be made: a local fit from the configured values is enough for the record
        fit = lsq_fit(problem, task.nominal, refit_budget)
        evaluations = fit.evaluations
    say(f"declared model: J = {fit.J:.4g} ({evaluations} evaluations)")
    return fit


def unexplained_force(
    task: Task | JointTask, ref: References, keep: NDArray | None, fit: Fit, files: Sequence[str]
) -> tuple[Unexplained, tuple[str, ...]]:
    """The strut force the declared model misses, non-parametrically (from the first run alone when several are
    fitted jointly), and the notes to add."""
    joint = isinstance(task, JointTask)
    first, first_ref = (task.tasks[0], ref[0]) if joint else (task, ref)
    first_keep = None if keep is None else keep[: first.residual_samples]
    missing = estimate_unexplained(first, first_ref, fit.names, fit.x, keep=first_keep)
    release_if_handing_back()  # a long record's: the estimate's freed heap (~30 MiB) back (core/allocator.py)
    notes = (f"the unexplained strut force is estimated from the first run ({files[0]}) alone",) if joint else ()
    return missing, notes


def sampling_notes(R_total: int, R_train: int, long: bool) -> tuple[str, ...]:
    """What the report says of the samples the fits used: the held-out ones (R_train of R_total trained on), and a long
    record's screening window."""
    notes: tuple[str, ...] = ()
    if R_train < R_total:  # the same model and data as identify's one fit, but fewer samples: say so
        ratio = np.sqrt(R_total / R_train)
        notes += (
            f"the 95 % intervals come from the {R_train} training residuals ({R_total - R_train} held out for the "
            f"validation J) with the residual's own variance: about {ratio:.2f} x wider than vehid identify's on the "
            "whole run, which are the bound widened by sqrt(chi2) when the residual is not noise",
        )
    if long:
        notes += (
            f"a long record: the candidates' screening ran on the first {SCREEN_SAMPLES} samples of each run (their "
            "LR and validation J are the window's), and so did the estimate of the unexplained strut force and a "
            "declared model's global search (the linear car's first fit is Levenberg–Marquardt on the whole record); "
            "the polish, every re-fit, interval, removal test and claim on the whole record",
        )
    return notes


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
    progress: ProgressHook | None = None,
) -> Diagnosis:
    """Close the loop on the measured run `data_file`, or on several runs jointly (one parameter set; each run its
    own road, noise and offsets; J the wls over every run's residuals, the residual analysis per run); see the
    module doc; `progress` hears of each step (the declared fit, each candidate tested, each re-fit)."""
    t_start = time.perf_counter()
    say = log or (lambda _msg: None)
    step = progress or (lambda _stage, _done, _total: None)
    config = prepare_config(config)
    files = as_paths(data_file)
    task = build_tasks(config, files)
    ref = task.reference(0)
    R_total = task.residual_samples
    split = validation_split(config, task, ref, files, validate_file)
    R_train = int(R_total if split.keep is None else split.keep.sum())
    runs = task.tasks if isinstance(task, JointTask) else (task,)
    # each run's channels beside the configured model (one simulation each), read by the checks and the candidates
    views = tuple(t.channel_views() for t in runs)
    found = check_runs(runs, views)  # the measurement chain first: its faults are candidates beside the physics
    for f in found.problems:
        say(f"check {f.status}: {f.channel} {f.check}: {f.message}")
    rk4 = min(t.experiment.step for t in runs) if config.simulation.integrator == "rk4" else None  # (else newmark)
    specs = {**candidate_specs(config, rk4), **sensor_candidates(found, views[0])}
    del views  # each channel four times over the record (15 MB at 60 s, 1 kHz): not held under the fits (issue 26)
    limits, starts = candidate_ranges(specs)
    twin = exact_twin(task)
    car = CarLoop(task, ref, split, {"limits": limits, "start": starts}, files, analyse_residuals, twin)
    screen, head = screening(task, ref, split, car, specs, files) if is_long(task) else (None, car)
    # 0. can the data tell at all? (before any fit: length, noise, excitation)
    pre = precheck_vehicle(task, ref)
    # 1. the declared model: the linear car's by LM, else by the configured algorithm (a long record: on its
    # window), then polished
    step("declared fit", 0, 1)
    search = None if screen is None else screen.problem_for(task.names)[0]
    linear = car.linear_for(task.names)  # the linear car (a long record's: its normal equations, summed over blocks)
    fit = fit_declared(config, task, car.problem_for(task.names)[0], pre.ok, refit_budget, say, search, linear)
    del search, linear  # the first fit's problems not held on
    before = car.report(fit, ())
    step("declared fit", 1, 1)
    quality = assess_vehicle(task, ref, before, pre)
    notes = sampling_notes(R_total, R_train, screen is not None)
    subject = Subject(
        specs=specs, declared=frozenset(config.vehicle.effect_values()), problem_for=car.problem_for,
        validation_J=car.validation_J, residual_count=R_train, statistic=lambda _fit: chi2_statistic(R_train),
        scale=lambda f: f.J, noise_limit=chi2_limit(R_train), screen=screen, linear_for=car.linear_for,
    )  # fmt: skip
    # The strut force the declared model misses, non-parametrically: the loop reads it at its end (a residual left, or
    # terms that may imitate a law), so it is estimated in a thread beside round 1's fits (0.1-0.4 s of a 3 s
    # diagnosis); a long record's only once read, after the fits (two working sets at once: its peak memory).
    with ThreadPoolExecutor(1) as beside:
        estimate = functools.partial(unexplained_force, head.task, head.ref, head.split.keep, fit, files)
        if quality.ok and screen is None:
            estimate = beside.submit(estimate).result
        elif screen is not None:  # read after the last report: the fits' held vectors (up to 16 MB) let go first
            estimate = functools.partial(_released, (car.points, head.points), estimate)
        return close(
            subject, fit, before, car.report, quality, alpha=alpha, max_rounds=max_rounds,
            candidate_budget=candidate_budget, refit_budget=refit_budget, say=say, t_start=t_start,
            unexplained=estimate, chi2_residuals=R_total, validation_source=split.source,
            sigma_source=task.sigma_source, validation_from_file=validate_file is not None,
            data_files=tuple(map(str, files)) if car.joint else (), extra_notes=notes,
            checks=tuple(found.to_json()), unit=config.unit, progress=progress,
        )  # fmt: skip


def _released(
    points: Sequence[SinglePoints], then: Callable[[], tuple[Unexplained, tuple[str, ...]]]
) -> tuple[Unexplained, tuple[str, ...]]:
    """`then()` once the fits' held residual vectors are forgotten."""
    for held in points:
        held.clear()
    return then()


def screening(
    task: Task | JointTask, ref: References, split: ValidationSplit, car: CarLoop, specs: dict[str, Candidate],
    files: Sequence[str],
) -> tuple[Subject, CarLoop]:  # fmt: skip
    """A long record's screening subject (diagnose/window.py) and the car's loop on its window: the car's problems
    on the first SCREEN_SAMPLES samples of each run, its held-out blocks there (or the --validate run, whole)."""
    head = window_task(task)
    n = SCREEN_SAMPLES
    wref = tuple({k: v[:n] for k, v in r.items()} for r in ref) if car.joint else {k: v[:n] for k, v in ref.items()}
    if split.keep is None:  # a --validate run: the same validation data
        wsplit = ValidationSplit(split.task, split.reference, None, None, split.source)
    else:
        wsplit = validation_split(task.config, head, wref, files, None)
    twin = exact_twin(head) if car.twin is not None else None  # the linear car's known parameters: by LM there too
    wcar = CarLoop(head, wref, wsplit, car.ranges, car.files, analyse_residuals=False, twin=twin)
    R = int(head.residual_samples if wsplit.keep is None else wsplit.keep.sum())
    subject = Subject(
        specs=specs, declared=frozenset(), problem_for=wcar.problem_for, validation_J=wcar.validation_J,
        residual_count=R, statistic=lambda _fit: chi2_statistic(R), scale=lambda f: f.J, noise_limit=chi2_limit(R),
        linear_for=None if twin is None else wcar.linear_for,
    )  # fmt: skip
    return subject, wcar


def joint_chi2(analyses: Sequence[ResidualAnalysis]) -> float:
    """The residual power per sample over several runs' analyses: every run's squared weighted residuals over
    their count (each channel's own samples)."""
    total = sum(float(np.nansum(a.residual**2)) for a in analyses)
    count = sum(int(np.count_nonzero(np.isfinite(a.residual))) for a in analyses)
    return total / max(count, 1)
