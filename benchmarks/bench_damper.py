"""Damper model evaluations per second on the virtual bench (a benchmark, not a test).

One evaluation = one parameter set simulated over 3000 steps of the paper's sine (25 mm, 0.8 Hz, 1 ms),
the whole library path (`simulate_damper`: inputs prepared, compiled RK4, stability check). Medians of
repeats; one thread. Target (issue 5): >= 5000 evaluations/s on one core for a Bouc-Wen damper.
Run: python benchmarks/bench_damper.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np

from vehid_cli.models.bench import sine
from vehid_cli.models.damper import default_values
from vehid_cli.sim.bench import simulate_damper
from vehid_cli.systems.damper.fit import DamperSpec

CASES = {
    "viscous": ((), dict(c0=1500.0)),
    "bingham": ((), dict(c0=700.0, fc=80.0, v_eps=0.01)),
    "bouc_wen": ((), dict(c0=1500.0, k0=500.0, c1=20000.0, alpha=800.0, beta=3e5, gamma=3e5, delta=200.0)),
    "bouc_wen + backlash": ((), dict(c0=1500.0, k0=500.0, c1=20000.0, alpha=800.0, beta=3e5, gamma=3e5, delta=200.0,
                                      gap=0.002)),
    "generalized_bouc_wen (m = 1)": ((1,), {}),
    "force_map (5 x 3) + lag/delay": ((5, 3), dict(T_reb_rise=0.02, tau_reb_rise=0.01)),
}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    h = sine(0.025, 0.8, 2.4, 1e-3)  # 3001 samples
    print(
        f"# {platform.node()} {platform.machine()}, python {platform.python_version()}; {h.t.size - 1} steps, RK4 1 ms"
    )
    print(f"{'model':<32} {'batch':>5} {'median s/call':>14} {'evals/s':>10}")
    for label, (table, values) in CASES.items():
        model = label.split(" ")[0]
        v = default_values(model, table)
        if model == "force_map":
            nv, nu = table
            v.update({f"v_node_{i + 1}": x for i, x in enumerate(np.linspace(-0.3, 0.3, nv))})
            v.update({f"u_node_{j + 1}": x for j, x in enumerate(np.linspace(0, 1, nu))})
            v.update({f"F_{i + 1}_{j + 1}": 3000 * (i - nv // 2) * (1 + j) for i in range(nv) for j in range(nu)})
            v.update(nv=nv, nu=nu)
        v.update(values)
        spec = DamperSpec(model, v, table)
        for batch in (1, 20):
            rows = np.repeat(spec.row()[None, :], batch, axis=0)
            simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u)  # compile
            times = []
            for _ in range(args.repeats):
                start = time.perf_counter()
                simulate_damper(spec.damper, rows, h.t, h.x, h.v, h.u)
                times.append(time.perf_counter() - start)
            s = statistics.median(times)
            print(f"{label:<32} {batch:>5} {s:>14.5f} {batch / s:>10.0f}")


if __name__ == "__main__":
    main()
