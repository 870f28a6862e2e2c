"""The full car with effects (``models.effects``) through the compiled fixed-step kernel, batched.

M qdd + C qd + K q + D' f(d, dd, z) = B y with the linear M, C, K, B of the config and f the composite
effect law (``models.effects``, composed from the registry). Struts: the four suspensions, d = [G, -I] q
(``fullcar_struts``), and, when
``tyre_damping`` is present, the four tyres, d = x_i - y_i (D rows [0, I], E rows -I).

The integrator is RK4 (order 4) or Newmark (order 2), chosen explicitly by the caller; `substeps`
integrates at dt / substeps on the road interpolated linearly between samples (the kernel's own
first-order-hold assumption, so the input is the same) and returns every substeps-th sample.
The car starts at rest on the linear static equilibrium of the first road sample (effect forces vanish
there when the road starts level, as every configured road does).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..models.effects import effect_rows
from ..models.fullcar import N_CORNERS, N_DOF, FullCarMatrices
from .kernel import KernelResult, integrate, integrate_blocks, no_force
from .linear import Response

BLOCK_SAMPLES = 2048  # samples of a long record's block (`effects_blocks`): 13 cars' trajectories in about 6 MB


def fullcar_struts(mats: FullCarMatrices) -> NDArray:
    """D (..., 4, 7) = [G, -I]: suspension deflection of each corner (body point minus wheel) [m]."""
    D = np.zeros(mats.batch_shape + (N_CORNERS, N_DOF))
    D[..., :, :3] = mats.G
    D[..., :, 3:] = -np.eye(N_CORNERS)
    return D


def simulate_fullcar(
    mats: FullCarMatrices,
    road: ArrayLike,
    dt: float,
    method: Literal["rk4", "newmark"],
    force=no_force,
    params: ArrayLike | None = None,
    n_z: int = 0,
) -> tuple[Response, KernelResult]:
    """The full car with a strut force law added at each corner (on top of its linear springs and dampers).

    Returns the Response (batch flattened to (P, n, .), or (n, .) for one car) and the raw kernel result.
    """
    P = int(np.prod(mats.batch_shape, dtype=int))
    res = integrate(
        method,
        mats.M.reshape(P, N_DOF, N_DOF),
        mats.C.reshape(P, N_DOF, N_DOF),
        mats.K.reshape(P, N_DOF, N_DOF),
        mats.B.reshape(P, N_DOF, N_CORNERS),
        road,
        dt,
        force,
        params,
        n_z,
        D=fullcar_struts(mats).reshape(P, N_CORNERS, N_DOF),
    )
    G = np.broadcast_to(mats.G, mats.batch_shape + (N_CORNERS, 3)).reshape(P, N_CORNERS, 3)
    Gt = np.swapaxes(G, -1, -2)
    q, qd, qdd = res.q, res.qd, res.qdd
    disp, acc = q[..., :3] @ Gt, qdd[..., :3] @ Gt
    if mats.batch_shape == ():
        q, qd, qdd, disp, acc = q[0], qd[0], qdd[0], disp[0], acc[0]
    t = np.arange(q.shape[-2]) * dt
    return Response(t=t, q=q, qd=qd, qdd=qdd, disp=disp, acc=acc), res


def upsample(road: NDArray, substeps: int) -> NDArray:
    """Road (..., n, 4) sampled every dt -> every dt / substeps, linear between the original samples."""
    if substeps == 1:
        return road
    n = road.shape[-2]
    frac = np.arange(substeps) / substeps  # (s,)
    start, step = road[..., :-1, None, :], np.diff(road, axis=-2)[..., :, None, :]
    fine = (start + frac[:, None] * step).reshape(road.shape[:-2] + ((n - 1) * substeps, road.shape[-1]))
    return np.concatenate([fine, road[..., -1:, :]], axis=-2)


@dataclass(frozen=True)
class _EffectsSystem:
    """A batch of cars with effects as the kernel's structure: the flattened (P, ...) matrices, struts and the
    composite law, the batch shape and the body points' rows G (P, 3, nb)."""

    batch: tuple[int, ...]
    M: NDArray
    C: NDArray
    K: NDArray
    B: NDArray
    G: NDArray
    D: NDArray
    E: NDArray
    law: object
    rows: NDArray
    n_z: int


def _effects_system(mats: FullCarMatrices, cf, cr, effects, road: NDArray, substeps: int, points) -> _EffectsSystem:
    """Check the inputs of `simulate_effects` and build the kernel's structure of its batch."""
    G = mats.G if points is None else np.asarray(points, dtype=float)
    if road.ndim != 2 or road.shape[-1] != N_CORNERS:
        raise ValueError(f"road must be (n, 4), got {road.shape}")
    if int(substeps) < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    shapes = [mats.batch_shape, np.shape(cf), np.shape(cr), G.shape[:-2]]
    shapes += [np.shape(v) for params in effects.values() for v in params.values()]
    batch = np.broadcast_shapes(*shapes)
    P = int(np.prod(batch, dtype=int))
    es = effect_rows(effects, cf, cr, batch)

    def flat(X: NDArray) -> NDArray:
        return np.broadcast_to(X, batch + X.shape[-2:]).reshape((P,) + X.shape[-2:])

    M, C, K, B, G = (flat(X) for X in (mats.M, mats.C, mats.K, mats.B, G))
    D = flat(fullcar_struts(mats))
    E = np.zeros((N_CORNERS, N_CORNERS))
    if es.tyres:
        tyre = np.zeros((P, N_CORNERS, N_DOF))
        tyre[:, :, 3:] = np.eye(N_CORNERS)
        D = np.concatenate([D, tyre], axis=1)
        E = np.concatenate([E, -np.eye(N_CORNERS)], axis=0)
    return _EffectsSystem(batch, M, C, K, B, G, D, E, es.law, es.rows, es.n_z)


def _response(sys_: _EffectsSystem, res: KernelResult, substeps: int, t: NDArray) -> Response:
    """The Response (batch..., n, .) of the kernel's trajectories at every substeps-th sample, at times t."""
    q, qd, qdd = (X[:, ::substeps] for X in (res.q, res.qd, res.qdd))
    Gt = np.swapaxes(sys_.G, -1, -2)
    disp, acc = q[..., :3] @ Gt, qdd[..., :3] @ Gt

    def shaped(X: NDArray) -> NDArray:
        return X.reshape(sys_.batch + X.shape[1:])

    return Response(t=t, q=shaped(q), qd=shaped(qd), qdd=shaped(qdd), disp=shaped(disp), acc=shaped(acc))


def simulate_effects(
    mats: FullCarMatrices,
    cf: ArrayLike,
    cr: ArrayLike,
    effects: Mapping[str, Mapping[str, ArrayLike]],
    road: ArrayLike,
    dt: float,
    method: Literal["rk4", "newmark"] = "rk4",
    substeps: int = 1,
    points: ArrayLike | None = None,
) -> Response:
    """Responses of a batch of cars with effects to the road (n, 4) [m] sampled every dt [s].

    cf, cr: the configured linear damping [N s/m] of each car (backlash and lag act on that damper);
    effects: effect name -> {parameter: value (scalar or array of the batch shape)}. The batch is the
    broadcast of the matrices' batch and the effect values' shapes; arrays come back as (batch..., n, k)
    like ``sim.linear.simulate``; `disp` and `acc` at the body `points` (..., nb, 3) (default the corners').
    """
    road = np.asarray(road, dtype=float)
    sys_ = _effects_system(mats, cf, cr, effects, road, substeps, points)
    substeps = int(substeps)
    res = integrate(method, sys_.M, sys_.C, sys_.K, sys_.B, upsample(road, substeps), dt / substeps, sys_.law,
                    sys_.rows, sys_.n_z, D=sys_.D, E=sys_.E)  # fmt: skip
    return _response(sys_, res, substeps, np.arange(road.shape[0]) * dt)


def effects_blocks(
    mats: FullCarMatrices,
    cf: ArrayLike,
    cr: ArrayLike,
    effects: Mapping[str, Mapping[str, ArrayLike]],
    road: ArrayLike,
    dt: float,
    substeps: int = 1,
    points: ArrayLike | None = None,
    block: int = BLOCK_SAMPLES,
) -> Iterator[tuple[int, Response]]:
    """`simulate_effects` (RK4) in time blocks of `block` samples: yields (first sample, the Response of the block's
    samples), the same numbers as one call (the kernel's state carried from block to block; a last block of one
    sample joins the one before), holding one block's trajectories at a time: a long record's whole trajectories
    are about 18 MB per car, its channels 4."""
    road = np.asarray(road, dtype=float)
    sys_ = _effects_system(mats, cf, cr, effects, road, substeps, points)
    substeps = int(substeps)
    fine = upsample(road, substeps)
    blocks = integrate_blocks(sys_.M, sys_.C, sys_.K, sys_.B, fine, dt / substeps, sys_.law, sys_.rows, sys_.n_z,
                              D=sys_.D, E=sys_.E, block=block * substeps, tail=substeps + 1)  # fmt: skip
    for k0, res in blocks:
        first = k0 // substeps
        yield first, _response(sys_, res, substeps, (first + np.arange(-(-res.q.shape[1] // substeps))) * dt)
