"""Compiled fixed-step integrators (RK4, Newmark-beta) for linear structures with pluggable nonlinear forces.

The model, batched over P parameter sets (index p), with n_q coordinates q, n_s struts and n_z internal
states z of the force laws:

    M qdd + C qd + K q + D' f = B y(t),     d = D q + E y,   dd = D qd + E yd,
    f, zd = force(d, dd, z, params)

M, C, K, B the linear part; D maps coordinates to strut deflections (``sim.nonlinear.fullcar_struts`` gives
the full car's [G, -I]); E lets the road drive a strut directly (a damper on a test bench has n_q = 0 and d = y).
The road y is sampled every dt and linear between samples (first-order hold), the assumption of the
``exact`` linear path, so the linear car through this kernel differs from ``exact`` by the scheme
error only.

A force law is a numba-jitted function ``force(d (n_s,), dd (n_s,), z (n_z,), params (n_par,),
f_out (n_s,), zd_out (n_z,)) -> None`` writing the strut forces [N] (positive resisting positive
deflection, like k d) and the rates of its internal states. Bouc-Wen, friction, asymmetric damping,
backlash and lag all fit this shape; each law's params row is one candidate's parameters.

Two time loops, one per scheme, each in its module: RK4 (`sim/rk4.py`, the law inlined: the path of the
nonlinear car) and Newmark-beta (`sim/newmark.py`, the law passed as an argument); a test bench's prescribed motion
has its own (`sim/prescribed.py`). `integrate` here prepares the arrays and runs one of them over the batch.

Both evaluate the same rates (`sim/rates.py`: ``strut_motion``, the law, ``linear_rates``) with the same arithmetic as
dense loops over M^-1, B, C, K, D and E, in the same order, so results do not depend on the speed-ups:
M^-1, B, D and E enter as their nonzeros (the car's M^-1 is diagonal, B has one entry per wheel, a strut
touches four coordinates; RK4's loop is compiled for their pattern, the values read per system), C and K
transposed so that the rows' sums advance together. (Bit for bit with
finite numbers; a diverging candidate still turns NaN everywhere, through the dense C and K sums.)
"""

from __future__ import annotations

import dataclasses
import os
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.jit import cached_njit
from ..core.pools import as_done, shared_pool
from .newmark import newmark_loop
from .rk4 import nonzero_pattern, rk4_loop

RK4, NEWMARK = 0, 1
METHODS = {"rk4": RK4, "newmark": NEWMARK}


@cached_njit()
def no_force(d, dd, z, params, f_out, zd_out):  # pragma: no cover - compiled
    """The linear structure itself: no strut force, no internal state."""
    for i in range(f_out.shape[0]):
        f_out[i] = 0.0


@cached_njit()
def cubic_spring(d, dd, z, params, f_out, zd_out):  # pragma: no cover - compiled
    """f_i = k3 d_i^3 [N] in every strut, params = [k3 (N/m³)]: a hardening spring beside the linear one."""
    k3 = params[0]
    for i in range(f_out.shape[0]):
        f_out[i] = k3 * d[i] * d[i] * d[i]


@dataclass(frozen=True)
class KernelResult:
    """Trajectories of a batch of P systems at the n road samples."""

    q: NDArray  # (P, n, n_q) coordinates
    qd: NDArray  # (P, n, n_q) velocities
    qdd: NDArray  # (P, n, n_q) accelerations
    force: NDArray  # (P, n, n_s) strut forces [N]
    z: NDArray  # (P, n, n_z) internal states of the force law
    unconverged: NDArray  # (P,) Newmark steps whose fixed-point iteration did not converge (0 for RK4)
    state: NDArray | None = None  # (P, 2 n_q + n_z) [q, qd, z] at the last sample (RK4): where the next block resumes


def _batched(X: ArrayLike, P: int, ndim: int = 2) -> NDArray:
    """A fresh writeable C-contiguous (P, ...) copy: one array type, so numba compiles one specialisation."""
    X = np.asarray(X, dtype=float)
    return np.array(np.broadcast_to(X, (P,) + X.shape[-ndim:]), dtype=float, order="C")


def _nonzero_rows(X: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """The nonzero pattern of X (P, R, C), shared by the batch: per row the columns where any system has a
    nonzero, in column order, as columns (R, w) int64, values (P, R, w) and counts (R,) int64; w is the
    largest count (at least 1; slots past a row's count hold column 0, value 0). NaN counts as nonzero.

    The kernel sums only these, in the dense loops' order: the same numbers (an exact zero adds nothing)
    at a fraction of the work for the car's diagonal M^-1, the road's B (one column per wheel) and the
    struts' D = [G, -I] and E."""
    nonzero = np.any(X != 0.0, axis=0)
    counts = nonzero.sum(axis=-1)
    w = max(int(counts.max(initial=0)), 1)
    cols = np.argsort(~nonzero, axis=-1, kind="stable")[:, :w]  # nonzero columns first, in column order
    used = np.arange(w) < counts[:, None]
    cols = np.where(used, cols, 0)
    vals = np.where(used, X[:, np.arange(X.shape[1])[:, None], cols], 0.0)
    return (
        np.ascontiguousarray(cols, dtype=np.int64),
        np.ascontiguousarray(vals, dtype=float),
        np.ascontiguousarray(counts, dtype=np.int64),
    )


_THREADS: int | None = None  # threads one batch is split over (None: the cores this process may use)


def set_threads(n: int | None) -> None:
    """Split each batch over at most n threads (1: none; None: the cores this process may use). Pool workers
    of a campaign set 1: their parallelism is over runs."""
    global _THREADS
    _THREADS = n


def available_cores() -> int:
    """The cores this process may use (its CPU affinity)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def in_parallel(P: int, rows) -> None:
    """rows(slice) over the batch's P systems, split into contiguous parts over threads (the compiled loops
    release the GIL; each system is integrated alone, so results are the same as in one call). Only from the
    main thread: a caller already running threads (parallel candidate fits) keeps its own split."""
    k = min(_THREADS or available_cores(), P)
    if k <= 1 or threading.current_thread() is not threading.main_thread():
        rows(slice(0, P))
        return
    bounds = np.linspace(0, P, k + 1).astype(int)
    parts = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    for _ in as_done(shared_pool("kernel", k), rows, parts):  # threads started once per process (core/pools.py)
        pass


@dataclass(frozen=True)
class _Batch:
    """The arrays the compiled loops take, prepared once: M^-1, B, D, E as nonzeros, C and K transposed, the road
    (1 or P, n, n_u), the force law's params rows and the initial states."""

    P: int
    Mr: tuple
    Br: tuple
    Dr: tuple
    Er: tuple
    M: NDArray
    C: NDArray
    K: NDArray
    CT: NDArray
    KT: NDArray
    u: NDArray
    params: NDArray
    q0: NDArray
    z0: NDArray
    v0: NDArray

    def outputs(self, n_z: int, n: int | None = None, forces: bool = True) -> KernelResult:
        """Empty trajectories for the batch, of n samples (default the road's); without `forces` the strut forces
        and internal states are not kept (zero samples). One buffer for q, qd, qdd: an allocation this large is
        returned to the allocator whole and reused by the next call, where three separate ones page-fault afresh
        every call (~5 ms for a batch of 20 cars)."""
        P, nq, ns = self.P, self.M.shape[-1], self.Dr[0].shape[0]
        n = self.u.shape[1] if n is None else n
        out_q, out_v, out_a = np.empty((3, P, n, nq))
        kept = n if forces else 0
        return KernelResult(
            q=out_q, qd=out_v, qdd=out_a, force=np.empty((P, kept, ns)), z=np.empty((P, kept, n_z)),
            unconverged=np.zeros(P, dtype=np.int64), state=np.concatenate([self.q0, self.v0, self.z0], axis=1),
        )  # fmt: skip


def _prepare(M, C, K, B, road, params, n_z, D, E, q0, z0, v0=None) -> _Batch:
    """Every input as a (P, ...) array of one type; the static equilibrium K q0 = B y0 when q0 is not given, at
    rest when v0 is not."""
    road = np.asarray(road, dtype=float)
    shapes = [np.shape(X)[:-2] for X in (M, C, K, B)] + [road.shape[:-2]]
    P = int(np.prod(np.broadcast_shapes(*shapes), dtype=int))
    n, nu = road.shape[-2:]
    M, C, K, B = (_batched(X, P) for X in (M, C, K, B))
    nq = M.shape[-1]
    D = _batched(np.zeros((0, nq)) if D is None else D, P)
    ns = D.shape[-2]
    E = _batched(np.zeros((ns, nu)) if E is None else E, P)
    u = np.array(road.reshape(-1, n, nu), dtype=float, order="C")
    if params is None:
        params = np.zeros((P, 0))
    params = _batched(np.atleast_1d(params), P, ndim=1)
    q0 = np.linalg.solve(K, B @ np.broadcast_to(u[:, 0], (P, nu))[..., None])[..., 0] if q0 is None else q0
    q0 = _batched(q0, P, ndim=1)
    z0 = _batched(np.zeros(n_z) if z0 is None else z0, P, ndim=1)
    v0 = _batched(np.zeros(M.shape[-1]) if v0 is None else v0, P, ndim=1)
    Minv = np.linalg.inv(M)
    CT, KT = (np.ascontiguousarray(np.swapaxes(X, -1, -2)) for X in (C, K))
    Mr, Br, Dr, Er = (_nonzero_rows(X) for X in (Minv, B, D, E))
    return _Batch(P, Mr, Br, Dr, Er, M, C, K, CT, KT, u, params, q0, z0, v0)


def _run_rk4(b: _Batch, dt: float, force, out: KernelResult, start: int = 0) -> None:
    """The RK4 loop over the batch from sample `start` (out.state: where it resumes, then where it ended), split into
    contiguous parts over threads."""
    nq, ns, nu = b.M.shape[-1], b.Dr[0].shape[0], b.u.shape[2]
    run = rk4_loop(force, nq, ns, nu, nonzero_pattern(b.Mr, b.Br, b.Dr, b.Er))

    def rows(s: slice) -> None:
        def part(X):
            return (X[0], X[1][s], X[2])

        us = b.u if b.u.shape[0] == 1 else b.u[s]
        run(part(b.Mr), b.CT[s], b.KT[s], part(b.Br), part(b.Dr), part(b.Er), us, float(dt), b.params[s],
            out.state[s], int(start), out.q[s], out.qd[s], out.qdd[s], out.force[s], out.z[s])  # fmt: skip

    in_parallel(b.P, rows)


def _run_newmark(b: _Batch, dt: float, force, out: KernelResult) -> None:
    """The Newmark loop over the batch (the law passed as an argument: one thread)."""
    Khat_inv = np.linalg.inv(b.K + (2.0 / dt) * b.C + (4.0 / dt**2) * b.M)
    MT, KhT = (np.ascontiguousarray(np.swapaxes(X, -1, -2)) for X in (b.M, Khat_inv))
    newmark_loop(
        b.Mr, b.CT, b.KT, b.Br, b.Dr, b.Er, MT, KhT, b.u, float(dt), force, b.params, b.q0, b.z0, out.q, out.qd,
        out.qdd, out.force, out.z, out.unconverged,
    )  # fmt: skip


def integrate(
    method: Literal["rk4", "newmark"],
    M: ArrayLike,
    C: ArrayLike,
    K: ArrayLike,
    B: ArrayLike,
    road: ArrayLike,
    dt: float,
    force=no_force,
    params: ArrayLike | None = None,
    n_z: int = 0,
    D: ArrayLike | None = None,
    E: ArrayLike | None = None,
    q0: ArrayLike | None = None,
    z0: ArrayLike | None = None,
    v0: ArrayLike | None = None,
    start: int = 0,
    stop: int | None = None,
    forces: bool = True,
) -> KernelResult:
    """Integrate M qdd + C qd + K q + D' f(d, dd, z) = B y for a batch of systems at fixed step dt [s].

    Matrices are (P, ., .) or shared (., .); road (n, n_u) shared or (P, n, n_u), linear between samples;
    params (P, n_par) rows of the force law (shared if 1-D); D (n_s, n_q) and E (n_s, n_u) default to no
    struts. q0 defaults to the linear static equilibrium K q0 = B y0, z0 to zero, v0 (velocities) to zero.

    RK4 only: samples start .. stop - 1 of the record (the road is the whole record's), resuming from the state
    q0, v0, z0 at sample start - 1 (a block before's ``state``, or its last q, qd, z), with the numbers of one
    call over the record (tests/test_kernel.py); without `forces` the strut forces and internal states are not
    returned (zero samples: a long record's blocks keep only what they read).
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: choose from {sorted(METHODS)}")
    resumed = start != 0 or stop is not None or v0 is not None or not forces
    if method != "rk4" and resumed:
        raise ValueError("only the rk4 kernel resumes mid-record (start, stop, v0, forces)")
    if start > 0 and q0 is None:
        raise ValueError("resuming at a sample after the first needs the state there (q0, v0, z0)")
    batch = _prepare(M, C, K, B, road, params, n_z, D, E, q0, z0, v0)
    n = batch.u.shape[1]
    stop = n if stop is None else stop
    if not 0 <= start < stop <= n:
        raise ValueError(f"samples {start}..{stop} outside the road's 0..{n}")
    out = batch.outputs(n_z, stop - start, forces)
    if method == "rk4":
        _run_rk4(batch, dt, force, out, start)
    else:
        _run_newmark(batch, dt, force, out)
        out = dataclasses.replace(out, state=None)  # Newmark's loop does not report where it ended
    return out


def integrate_blocks(
    M: ArrayLike,
    C: ArrayLike,
    K: ArrayLike,
    B: ArrayLike,
    road: ArrayLike,
    dt: float,
    force=no_force,
    params: ArrayLike | None = None,
    n_z: int = 0,
    D: ArrayLike | None = None,
    E: ArrayLike | None = None,
    block: int = 4096,
    forces: bool = False,
    tail: int = 2,
) -> Iterator[tuple[int, KernelResult]]:
    """`integrate('rk4', ...)` over the record in time blocks of `block` samples, the state carried from each to
    the next: yields (first sample, KernelResult of the block), the same numbers as one call, with only a block's
    trajectories held at a time (a long record's whole trajectories are about 18 MB per car). A last block shorter
    than `tail` samples joins the one before (a one-sample block's products take BLAS's vector path, whose
    rounding differs). The batch is prepared once; the systems start at rest on the static equilibrium of the first
    road sample."""
    batch = _prepare(M, C, K, B, road, params, n_z, D, E, None, None)
    n = batch.u.shape[1]
    starts = list(range(0, n, max(1, block)))
    if len(starts) > 1 and n - starts[-1] < tail:
        starts.pop()
    state = None
    for start, stop in zip(starts, [*starts[1:], n], strict=True):
        out = batch.outputs(n_z, stop - start, forces)
        if state is not None:
            out.state[...] = state
        _run_rk4(batch, dt, force, out, start)
        state = out.state
        yield start, out
