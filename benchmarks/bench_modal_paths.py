"""The linear car's modal path piece by piece, each new piece beside the one it replaced, interleaved in one run on
ONE core (a benchmark, not a test; issue 26: the identification's path at >= 8000 evaluations/s).

* eigenvalues: A's by a compiled QR iteration (``sim.eigenvalues``) against LAPACK's through numpy (before);
* modes: A's eigenvalues (compiled) and the vectors from the 7 x 7 quadratic eigenproblem
  (``sim.modal._second_order_modes``) against LAPACK's eigenvectors and the inverse of their matrix
  (``sim.modal._kept_modes``, the path before);
* recursion + projection: each car's rows contiguous and padded to whole vectors (``sim.modal._modal_blocks``)
  against the block's cars interleaved row by row, 2 m + 4 columns (the layout before, its kernel copied here);
* the whole path (``Experiment.outputs``) with each of the two modes' paths, at batch 1, 20 and 100.

Each figure is the median of interleaved repeats in thread CPU time (the machine may be shared: compare the ratios
of one run). Threads are pinned to one before numpy loads.
Run: python benchmarks/bench_modal_paths.py --repeats 21
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402

from vehid_cli.config import load_config  # noqa: E402
from vehid_cli.identify.experiment import build_experiment  # noqa: E402
from vehid_cli.models.fullcar import N_DOF  # noqa: E402
from vehid_cli.sim import modal  # noqa: E402
from vehid_cli.sim.eigenvalues import eigenvalues  # noqa: E402
from vehid_cli.sim.kernel import set_threads  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@numba.njit(cache=True)
def interleaved_recursion(e, g, x0, u, out):  # pragma: no cover - compiled
    """The recursion as it was: out (n, P, 2 m + 4), the block's cars interleaved in each row (one road)."""
    P = out.shape[1]
    L = e.shape[0]
    m = L // P
    n = u.shape[1]
    er, ei = e.real.copy(), e.imag.copy()
    gr, gi = g.real.copy(), g.imag.copy()
    xr, xi = x0.real.copy(), x0.imag.copy()
    for k in range(n):
        for p in range(P):
            for j in range(m):
                out[k, p, j] = xr[p * m + j]
                out[k, p, m + j] = xi[p * m + j]
            for c in range(4):
                out[k, p, 2 * m + c] = u[0, k, c]
        if k == n - 1:
            break
        y0, y1, y2, y3 = u[0, k, 0], u[0, k, 1], u[0, k, 2], u[0, k, 3]
        for l in range(L):
            dr = gr[0, l] * y0 + gr[1, l] * y1 + gr[2, l] * y2 + gr[3, l] * y3
            di = gi[0, l] * y0 + gi[1, l] * y1 + gi[2, l] * y2 + gi[3, l] * y3
            xr_new = er[l] * xr[l] - ei[l] * xi[l] + dr
            xi[l] = er[l] * xi[l] + ei[l] * xr[l] + di
            xr[l] = xr_new


def interleaved_blocks(decay, a, b, z0, u, proj, out) -> None:
    """The blocks as they were: unpadded rows [Re x (m), Im x (m), y] of the block's cars interleaved, each car's
    projection a strided product."""
    P = out.shape[0]
    m = decay.size // P
    g, x0, padded = modal._shifted(decay, a, b, z0, u, proj)
    mp = modal._padded_modes(m)
    shifted = np.concatenate([padded[:, :m], padded[:, mp : mp + m], padded[:, 2 * mp :]], axis=1)
    n, width = u.shape[1], 2 * m + a.shape[0]
    count = -(-P // modal._block_size(n, width))
    size = -(-P // count)
    scratch = np.empty((n, min(P, size), width))
    for start in range(0, P, size):
        stop = min(P, start + size)
        lanes = slice(start * m, stop * m)
        block = scratch[:, : stop - start]
        interleaved_recursion(decay[lanes], np.ascontiguousarray(g[:, lanes]), x0[lanes], u, block)
        np.matmul(block.transpose(1, 0, 2), shifted[start:stop], out=out[start:stop])


def interleaved_median(fns: dict, repeats: int) -> dict[str, float]:
    """Median thread CPU time [s] of each callable, the callables interleaved in every repeat (after a warm-up)."""
    for fn in fns.values():
        fn()
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            start = time.thread_time()
            fn()
            times[k].append(time.thread_time() - start)
    return {k: statistics.median(v) for k, v in times.items()}


def batch_pieces(exp, values: dict[str, np.ndarray], batch: int) -> list[tuple[str, object, object]]:
    """(name, before, now) callables for one batch of cars."""
    p = exp.parameters(values)
    mats = exp.matrices(values)
    _, A, Bs, G, q0, u, MCK = modal._flatten(mats, exp.road, exp.layout.points(p))
    lam_k, w_k, V_k, W_k, _ = modal._second_order_modes(A, *MCK)
    m = lam_k.shape[1]
    decay, a, b = modal._foh_gains(lam_k, W_k @ Bs, exp.dt)
    z0 = (W_k[:, :, :N_DOF] @ q0[:, :, None])[..., 0].reshape(batch * m)
    proj = np.ascontiguousarray(np.random.default_rng(1).normal(size=(batch, 2 * m + 4, 8)))
    Y = np.empty((batch, exp.t.size, 8))
    original = modal._second_order_modes

    def lapack_outputs():
        """Experiment.outputs with LAPACK's eigenvectors and their inverse (the modes' path before)."""
        modal._second_order_modes = lambda A, M, C, K: modal._kept_modes(A)
        try:
            return exp.outputs(values)
        finally:
            modal._second_order_modes = original

    return [
        ("eigenvalues", lambda: np.linalg.eigvals(A), lambda: eigenvalues(A)),
        ("modes", lambda: modal._kept_modes(A), lambda: modal._second_order_modes(A, *MCK)),
        (
            "recursion + projection (8 cols)",
            lambda: interleaved_blocks(decay, a, b, z0, u, proj, Y),
            lambda: modal._modal_blocks(decay, a, b, z0, u, proj, Y),
        ),
        ("Experiment.outputs: LAPACK vectors", lapack_outputs, lambda: exp.outputs(values)),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    set_threads(1)
    cfg = load_config(ROOT / "configs" / "gokdag2015" / "base.yaml")
    exp = build_experiment(cfg)
    rng = np.random.default_rng(0)
    base = cfg.vehicle.values()
    print(f"# {exp.t.size} samples, one core, thread CPU time, medians of {args.repeats} interleaved repeats")
    print(f"{'piece':<34} {'batch':>5} {'before us/car':>14} {'now us/car':>11} {'before/now':>11}")
    for batch in (1, 20, 100):
        values = {k: base[k] * rng.uniform(0.7, 1.3, batch) for k in cfg.identify.unknowns}
        pieces = batch_pieces(exp, values, batch)
        for name, before, now in pieces:
            t = interleaved_median({"before": before, "now": now}, args.repeats)
            us = {k: v / batch * 1e6 for k, v in t.items()}
            print(f"{name:<34} {batch:>5} {us['before']:>14.1f} {us['now']:>11.1f} {t['before'] / t['now']:>11.3f}")


if __name__ == "__main__":
    main()
