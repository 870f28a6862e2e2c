"""Time to an estimate at the bound, per core, on the paper's case: vehid's `lsq` + `wls` campaign against a peer
written as a user would (scipy.optimize.least_squares around scipy.signal.lsim of the same car), same data, same
start points, same bounds, in the same process (a benchmark, not a test).

Issue 26, acceptance 1: vehid's time per run per core >= 30x faster than the peer's, NRE/CRLB <= 1.2. Printed: each
side's wall time per run on one core, evaluations per run and NRE/CRLB (root mean square over the runs of the
normalised relative error, over the bound's), the ratio; and, as further anchors, vehid's own previous path (scipy's
trust region on forward-difference Jacobians of the modal simulator, `Problem.linearised` removed) and lsq with
its last step confirmed by a linearisation (`optimizers.lsq.LAST_SD` = 0: the stopping rule before the last step
was taken on the residuals alone).
Run pinned to one thread:
    NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/bench_time_to_bound.py
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.signal
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.machine import host  # noqa: E402
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.config import load_config
from vehid_cli.core.streams import run_streams
from vehid_cli.models.fullcar import N_DOF
from vehid_cli.optimizers import lsq
from vehid_cli.systems import build_system

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"
OVERRIDES = ["identify.algorithm.name=lsq", "identify.objective=wls"]


def nre_over_bound(estimates: np.ndarray, truth: np.ndarray, bound_nre: float) -> float:
    """RMS over runs of sqrt(sum_j RE_j²) [%], over the bound's NRE RMS [%]."""
    re = 100.0 * (estimates - truth) / truth
    return float(np.sqrt(np.mean(np.sum(re**2, axis=1))) / bound_nre)


def peer_fit(system, index: int) -> tuple[np.ndarray, int]:
    """One run as a user would write it: the car's state space, its sensors' output matrices, scipy.signal.lsim
    (first-order hold, like vehid) from static equilibrium, least_squares on the weighted residuals (its default
    trust region and two-point Jacobian) from the run's start point in the same box."""
    task = system.task
    exp = task.experiment
    reference = system.reference(index)
    sigma = task.sigma
    names, lo, hi = task.names, task.lower, task.upper
    x0 = lo + (hi - lo) * run_streams(system.config.identify.seed, index).optimizer.random((1, lo.size))[0]
    t, road = exp.t, exp.road

    def residuals(x: np.ndarray) -> np.ndarray:
        p = exp.parameters(dict(zip(names, x, strict=True)))
        mats = exp.matrices(dict(zip(names, x, strict=True)))
        A, B = mats.state_space()
        G = exp.layout.points(p)  # corner rows [1, y, -x]
        C = np.vstack([G @ A[N_DOF : N_DOF + 3], np.hstack([G, np.zeros((4, 2 * N_DOF - 3))])])
        D = np.vstack([G @ B[N_DOF : N_DOF + 3], np.zeros((4, 4))])
        s0 = np.concatenate([np.linalg.solve(mats.K, mats.B @ road[0]), np.zeros(N_DOF)])
        _, y, _ = scipy.signal.lsim((A, B, C, D), road, t, X0=s0)
        return np.concatenate(
            [((reference[f] - y[:, k : k + 4]) / sigma[f]).ravel() for k, f in ((0, "acc"), (4, "disp"))]
        )

    fit = least_squares(residuals, x0, bounds=(lo, hi))
    return fit.x, int(fit.nfev + fit.njev * lo.size)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="vehid campaigns timed (median)")
    parser.add_argument("--peer-runs", type=int, default=10, help="runs the peer fits (of the campaign's 30)")
    args = parser.parse_args()
    threads = {k: os.environ.get(k) for k in ("NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    print(f"# {host()}, {os.cpu_count()} cores, threads {threads}")
    config = load_config(BASE, OVERRIDES)
    system = build_system(config)
    n_runs = system.runs
    run_campaign(config, jobs=1, system=system)  # compile and warm up

    class Differences:  # vehid's previous path: no exact linearisation, scipy's trf on forward differences
        def __getattr__(self, name):
            return getattr(system, name)

        def problem(self, reference):
            return dataclasses.replace(system.problem(reference), linearised=None)

    walls: dict[str, list[float]] = {k: [] for k in ("new", "old", "confirm", "peer")}
    cpus: dict[str, list[float]] = {k: [] for k in walls}

    def timed(key: str, fn, per: int):  # wall and CPU time (the process's: one thread) per run of fn()
        wall, cpu = time.perf_counter(), time.process_time()
        out = fn()
        walls[key].append((time.perf_counter() - wall) / per)
        cpus[key].append((time.process_time() - cpu) / per)
        return out

    def confirmed():  # lsq with the last step confirmed by a linearisation (the rule before LAST_SD)
        last_sd, lsq.LAST_SD = lsq.LAST_SD, 0.0
        try:
            return run_campaign(config, jobs=1, system=system)
        finally:
            lsq.LAST_SD = last_sd

    new = old = confirm = None
    peer_estimates, peer_evals = [], []
    for rep in range(args.repeats):
        new = timed("new", lambda: run_campaign(config, jobs=1, system=system), n_runs)
        old = timed("old", lambda: [system.__class__.identify_run(Differences(), i) for i in range(n_runs)], n_runs)
        confirm = timed("confirm", confirmed, n_runs)
        runs = range(rep * args.peer_runs // args.repeats, (rep + 1) * args.peer_runs // args.repeats)
        for i in runs:  # the peer's runs spread over the repeats, interleaved with vehid's campaigns
            x, evals = timed("peer", lambda i=i: peer_fit(system, i), 1)
            peer_estimates.append(x)
            peer_evals.append(evals)
    truth, bound = new.truth, new.bound.nre_rms_percent
    t = {k: statistics.median(w) for k, w in walls.items()}
    c = {k: statistics.median(w) for k, w in cpus.items()}
    rows = [
        ("peer: least_squares + lsim", "peer", np.mean(peer_evals),
         nre_over_bound(np.array(peer_estimates), truth, bound)),
        ("vehid lsq before (trf, differences)", "old", np.mean([r.evaluations for r in old]),
         nre_over_bound(np.array([r.estimate for r in old]), truth, bound)),
        ("vehid lsq, last step linearised", "confirm", np.mean([r.evaluations for r in confirm.records]),
         nre_over_bound(np.array([r.estimate for r in confirm.records]), truth, bound)),
        ("vehid lsq (exact sensitivities, LM)", "new", np.mean([r.evaluations for r in new.records]),
         nre_over_bound(np.array([r.estimate for r in new.records]), truth, bound)),
    ]  # fmt: skip
    print(f"paper's case, {n_runs} runs (peer: {len(walls['peer'])} of them), one core, medians (wall; CPU)")
    for name, key, evals, ratio in rows:
        speed = f"peer/this {t['peer'] / t[key]:6.1f}x ({c['peer'] / c[key]:5.1f}x CPU)"
        print(f"{name:<40} {t[key] * 1e3:8.1f} ms per run ({c[key] * 1e3:6.1f} CPU)  {evals:6.1f} evaluations  "
              f"NRE/CRLB {ratio:5.2f}  {speed}")  # fmt: skip


if __name__ == "__main__":
    main()
