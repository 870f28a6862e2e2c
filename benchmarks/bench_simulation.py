"""Model evaluations per second of the full-car simulation paths on ONE core (a benchmark, not a test).

One evaluation = one parameter set simulated over the paper's experiment (3000 samples, 4 channels),
including assembling its matrices and discretising them: every candidate of an identification is new.
The nonlinear car: the paper's car with Bouc-Wen hysteresis in every strut (configs/effects/hysteresis.yaml)
through the library path (``Experiment.simulate``: matrices, effect rows, compiled RK4 over the 3000
samples, responses), candidates varying the car and the Bouc-Wen force; the issue's target is >= 500/s
at a population of 20 on one core.
The linear car (issue 26): `integrator: exact` through the identification's path (``Experiment.outputs``: only
the layout's channels) and through the full ``Response`` (every coordinate, velocity, acceleration and body point),
at batch 1, 20 and 100, each beside the scipy.signal.lsim loop at the same batch in the same run; the target is
>= 8000/s at batch 20 and 100 on one core.
Each figure is the median of several repeats; the machine is noisy, so compare medians of one run only.
Threads are pinned to one (numba, OpenBLAS/MKL/OpenMP) before numpy loads, for the one-core figure.
Run: make bench   (or: python benchmarks/bench_simulation.py --repeats 7)
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy import signal  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.machine import host  # noqa: E402
from vehid_cli.config import load_config  # noqa: E402
from vehid_cli.identify.experiment import build_experiment  # noqa: E402
from vehid_cli.sim.kernel import cubic_spring, set_threads  # noqa: E402
from vehid_cli.sim.linear import simulate  # noqa: E402
from vehid_cli.sim.modal import statespace_foh  # noqa: E402
from vehid_cli.sim.nonlinear import simulate_fullcar  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def timed(fn, repeats: int) -> float:
    """Median wall time [s] of fn() over `repeats` calls, after one warm-up call (which also compiles)."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cfg = load_config(ROOT / "configs" / "gokdag2015" / "base.yaml")
    exp = build_experiment(cfg)
    road, dt = exp.road, exp.dt
    rng = np.random.default_rng(0)
    print(f"# {host()}, {os.cpu_count()} cpus, python {platform.python_version()}")
    set_threads(1)  # one core: the kernel would otherwise split each batch over the process's cores
    threads = ", ".join(f"{v}={os.environ[v]}" for v in ("NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS"))
    print(f"# numpy {np.__version__}, scipy {scipy.__version__}, numba {numba.__version__}, {threads}")
    print(f"# experiment: {exp.t.size} samples, dt = {dt * 1e3:g} ms, 4 acceleration channels; repeats {args.repeats}")

    def candidates(batch: int) -> dict[str, np.ndarray]:
        """The identification's unknowns drawn in their [0.7, 1.3] search box."""
        base = cfg.vehicle.values()
        return {k: base[k] * rng.uniform(0.7, 1.3, batch) for k in cfg.identify.unknowns}

    def lsim_loop(values: dict[str, np.ndarray]) -> None:
        """scipy.signal.lsim one candidate at a time (it takes one system), matrices included."""
        for i in range(next(iter(values.values())).size):
            mats = exp.matrices({k: v[i] for k, v in values.items()})
            A, Bs = mats.state_space()
            Cd = np.zeros((4, 14))
            Cd[:, :3] = mats.G
            signal.lsim((A, Bs, Cd, np.zeros((4, 4))), road, exp.t)

    def kernel(method: str, force=None, k3: float = 0.0):
        def run(values):
            if force is None:
                return simulate_fullcar(exp.matrices(values), road, dt, method)
            return simulate_fullcar(exp.matrices(values), road, dt, method, force, [k3])

        return run

    hyst_cfg = load_config(ROOT / "configs" / "effects" / "hysteresis.yaml")
    hyst_exp = build_experiment(hyst_cfg)
    hyst_truth = hyst_cfg.vehicle.values()
    hyst_alpha = hyst_cfg.vehicle.effect_values()["hysteresis"]

    def bouc_wen_candidates(batch: int) -> dict[str, np.ndarray]:
        """The car's unknowns and the Bouc-Wen force per unit z (alpha_f, alpha_r) in the [0.7, 1.3] box."""
        values = {k: hyst_truth[k] * rng.uniform(0.7, 1.3, batch) for k in hyst_cfg.identify.unknowns}
        for name in ("alpha_f", "alpha_r"):
            values[f"hysteresis.{name}"] = hyst_alpha[name] * rng.uniform(0.7, 1.3, batch)
        return values

    paths = [
        ("exact: channels (identify)", exp.outputs, (1, 20, 100)),
        ("exact: full Response", lambda v: exp.simulate(v).acc, (1, 20, 100)),
        ("state-space FOH (numba)", lambda v: statespace_foh(exp.matrices(v), road, dt), (1, 20, 100)),
        ("exact-reference (numpy)", lambda v: simulate(exp.matrices(v), road, dt, "exact-reference"), (1, 20)),
        ("newmark (numpy)", lambda v: simulate(exp.matrices(v), road, dt, "newmark"), (1, 20)),
        ("scipy.signal.lsim (loop)", lsim_loop, (1, 20, 100)),
        ("kernel rk4, linear car", kernel("rk4"), (1, 20)),
        ("kernel newmark, linear car", kernel("newmark"), (1, 20)),
        ("kernel rk4, cubic strut", kernel("rk4", cubic_spring, 5e7), (20,)),
        ("kernel newmark, cubic strut", kernel("newmark", cubic_spring, 5e7), (20,)),
        ("nonlinear car rk4, Bouc-Wen", lambda v: hyst_exp.simulate(v).acc, (1, 20, 100)),
    ]
    try:
        import control  # noqa: F401  (optional: compared only if already installed)
    except ImportError:
        print("# python-control not installed: forced_response not compared")
    else:

        def control_loop(values: dict[str, np.ndarray]) -> None:
            for i in range(next(iter(values.values())).size):
                mats = exp.matrices({k: v[i] for k, v in values.items()})
                A, Bs = mats.state_space()
                Cd = np.zeros((4, 14))
                Cd[:, :3] = mats.G
                control.forced_response(control.ss(A, Bs, Cd, np.zeros((4, 4))), exp.t, road.T)

        paths.append(("control.forced_response (loop)", control_loop, (1,)))

    rows = []
    for name, fn, batches in paths:
        for batch in batches:
            values = bouc_wen_candidates(batch) if "Bouc-Wen" in name else candidates(batch)
            seconds = timed(lambda f=fn, v=values: f(v), args.repeats)
            rows.append((name, batch, seconds, batch / seconds))
    lsim = {batch: rate for name, batch, _, rate in rows if name.startswith("scipy")}
    print(f"{'path':<30} {'batch':>5} {'median s/call':>14} {'evals/s':>10} {'lsim evals/s':>13} {'x lsim':>8}")
    for name, batch, seconds, rate in rows:
        anchor = lsim.get(batch, lsim[1])  # the lsim loop at the same batch, measured in this run
        print(f"{name:<30} {batch:>5} {seconds:>14.5f} {rate:>10.1f} {anchor:>13.1f} {rate / anchor:>8.1f}")
    linear_car(rows, lsim, exp.t.size)
    bouc_wen = next(rate for name, batch, _, rate in rows if "Bouc-Wen" in name and batch == 20)
    verdict = "meets" if bouc_wen >= 500 else "MISSES"
    print(
        f"# nonlinear car, Bouc-Wen struts, RK4 over {exp.t.size} samples, population 20, one core: "
        f"{bouc_wen:.0f} evaluations/s ({verdict} the target of 500/s)"
    )


def linear_car(rows: list[tuple[str, int, float, float]], lsim: dict[int, float], samples: int) -> None:
    """The linear car's lines (issue 26): each path at batch 1, 20, 100 beside the lsim loop of this run at the
    same batch; the batch-size cliff (batch 100 at least as fast as batch 20); the identification's path against
    the target of 8000/s at batch 20 and 100."""
    for name in ("exact: channels (identify)", "exact: full Response"):
        rate = {batch: r for n, batch, _, r in rows if n == name}
        parts = [f"batch {b}: {rate[b]:.0f}/s ({rate[b] / lsim[b]:.0f}x lsim's {lsim[b]:.0f}/s)" for b in (1, 20, 100)]
        line = f"# linear car, {name}, {samples} samples, one core: " + "; ".join(parts)
        line += (
            "; no batch-size cliff" if rate[100] >= rate[20] else f"; batch 100 at {rate[100] / rate[20]:.2f}x batch 20"
        )
        if name.startswith("exact: channels"):
            verdict = "meets" if min(rate[20], rate[100]) >= 8000 else "MISSES"
            line += f"; {verdict} the target of 8000/s at batch 20 and 100"
        print(line)


if __name__ == "__main__":
    main()
