"""Damper model evaluations per second on the virtual bench (a benchmark, not a test).

One evaluation = one parameter set simulated over 3000 RK4 steps of 1 ms: the paper's sine (25 mm, 0.8 Hz) and,
for the models with a control input, the sawtooth with the paper's control steps (so lag and delays act), through
the whole library path (`simulate_damper`: inputs prepared, compiled RK4, stability check). Every model is timed on
its fast path (all candidates of the batch at once, `models.damper.*_lanes`) and, interleaved in the same run, on
its anchor: the reference path (each candidate after the other through the scalar law, `reference=True`, the same
forces bit for bit). Time is this process's CPU time (one thread: its wall time on a quiet machine; on a loaded one
the wall time also counts the other processes' turns); medians of repeats and the best.
Target (issue 26): every model >= 5000 evaluations/s at batch 20 on one core.
Run: NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/bench_damper.py [--repeats 9]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.machine import host  # noqa: E402
from vehid_cli.models.bench import BenchHistory, sawtooth, sine
from vehid_cli.models.damper import default_values
from vehid_cli.sim.bench import simulate_damper
from vehid_cli.systems.damper.fit import DamperSpec

BW = dict(c0=1500.0, k0=500.0, c1=20000.0, alpha=800.0, beta=3e5, gamma=3e5, delta=200.0)
LAG_DELAY = dict(T_comp_rise=0.01, T_comp_fall=0.012, T_reb_rise=0.02, T_reb_fall=0.015, tau_comp_rise=0.003,
                 tau_comp_fall=0.004, tau_reb_rise=0.01, tau_reb_fall=0.005)  # fmt: skip
CASES = {  # label: (model, table shape, values, bench)
    "gas_spring": ("gas_spring", (), dict(k1=2000.0, x0=-0.01), "sine"),
    "viscous": ("viscous", (), dict(c0=1500.0), "sine"),
    "bingham": ("bingham", (), dict(c0=700.0, fc=80.0, v_eps=0.01), "sine"),
    "bouc_wen": ("bouc_wen", (), BW, "sine"),
    "bouc_wen + backlash": ("bouc_wen", (), dict(BW, gap=0.002), "sine"),
    "generalized_bouc_wen (m = 1)": ("generalized_bouc_wen", (1,), {}, "sine"),
    "generalized_bouc_wen (m = 3) + lag/delay": ("generalized_bouc_wen", (3,), LAG_DELAY, "sawtooth"),
    "force_map (5 x 3) + lag/delay": ("force_map", (5, 3), dict(T_reb_rise=0.02, tau_reb_rise=0.01), "sine"),
    "force_map (5 x 3) + lag/delay, steps": ("force_map", (5, 3), LAG_DELAY, "sawtooth"),
}  # fmt: skip


def spec_of(model: str, table: tuple[int, ...], values: dict) -> DamperSpec:
    v = default_values(model, table)
    if model == "force_map":  # a map rising in velocity and control input
        nv, nu = table
        v.update({f"v_node_{i + 1}": x for i, x in enumerate(np.linspace(-0.3, 0.3, nv))})
        v.update({f"u_node_{j + 1}": x for j, x in enumerate(np.linspace(0, 1, nu))})
        v.update({f"F_{i + 1}_{j + 1}": 3000 * (i - nv // 2) * (1 + j) for i in range(nv) for j in range(nu)})
    if model == "generalized_bouc_wen" and table[0] > 1:  # sets that change along u and between the strokes
        (m,) = table
        for p, value in BW.items():
            for side, k in (("comp", 1.0), ("reb", 1.2)):
                v.update({f"{p}_{side}_{j + 1}": value * k * (1 + 0.3 * j) for j in range(m)})
    v.update(values)
    return DamperSpec(model, v, table)


def rows_of(spec: DamperSpec, batch: int) -> np.ndarray:
    """`batch` candidates around the spec: every parameter a fit identifies moved by up to +-5 % (not the table sizes,
    the nodes and v_switch, which the configs hold fixed: candidates that share them share Eq. 5's switch)."""
    rows = np.repeat(spec.row()[None, :], batch, axis=0)
    fixed = ("m", "nv", "nu", "v_switch")
    vary = [i for i, n in enumerate(spec.names) if n not in fixed and "node" not in n]
    rng = np.random.default_rng(0)
    rows[1:, vary] *= 1 + 0.1 * (rng.random((batch - 1, len(vary))) - 0.5)
    return rows


def alternated(runs: dict, repeats: int, batch: int) -> dict:
    """Evaluations per CPU second of each run (`batch` evaluations per call), `repeats` times, the runs alternating
    call by call after one warm-up call each (which also compiles)."""
    for run in runs.values():
        run()
    out: dict = {name: [] for name in runs}
    for _ in range(repeats):
        for name, run in runs.items():
            start = time.process_time()
            run()
            out[name].append(batch / (time.process_time() - start))
    return out


def rates(spec: DamperSpec, rows: np.ndarray, h: BenchHistory, repeats: int) -> tuple[list[float], list[float]]:
    """Evaluations/s of the fast path and of the reference path, timed alternately."""
    runs = {ref: (lambda ref=ref: simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u, reference=ref)) for ref in
            (False, True)}  # fmt: skip
    out = alternated(runs, repeats, len(rows))
    return out[False], out[True]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--batches", default="1,20", help="comma-separated batch sizes")
    parser.add_argument("--only", default="", help="only the models whose label contains this (and bouc_wen)")
    args = parser.parse_args()
    benches = {"sine": sine(0.025, 0.8, 2.4, 1e-3), "sawtooth": sawtooth(cycles=4.5)}  # 3001 samples each
    print(
        f"# {host()}, python {platform.python_version()}; "
        f"{benches['sine'].t.size - 1} steps, RK4 1 ms; evaluations per CPU second, median (best) of {args.repeats}"
    )
    print(f"{'model':<42} {'bench':<8} {'batch':>5} {'fast path':>16} {'reference':>14} {'x ref':>6} {'/ BW':>5}")
    for batch in (int(b) for b in args.batches.split(",")):
        bouc_wen = None
        for label, (model, table, values, bench) in CASES.items():
            if args.only not in label and label != "bouc_wen":
                continue
            spec, h = spec_of(model, table, values), benches[bench]
            fast, ref = rates(spec, rows_of(spec, batch), h, args.repeats)
            f, r = statistics.median(fast), statistics.median(ref)
            bouc_wen = f if label == "bouc_wen" else bouc_wen
            versus = f"{f / bouc_wen:5.2f}" if bouc_wen else "    -"
            print(
                f"{label:<42} {bench:<8} {batch:>5} {f:>8.0f} ({max(fast):>5.0f}) {r:>6.0f} ({max(ref):>5.0f}) "
                f"{f / r:>6.1f} {versus}"
            )


if __name__ == "__main__":
    main()
