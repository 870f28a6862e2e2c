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

from collections.abc import Mapping
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..models.effects import effect_rows
from ..models.fullcar import N_CORNERS, N_DOF, FullCarMatrices
from .kernel import KernelResult, integrate, no_force
from .linear import Response


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
    G = mats.G if points is None else np.asarray(points, dtype=float)
    road = np.asarray(road, dtype=float)
    if road.ndim != 2 or road.shape[-1] != N_CORNERS:
        raise ValueError(f"road must be (n, 4), got {road.shape}")
    if int(substeps) < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    substeps = int(substeps)
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
    res = integrate(method, M, C, K, B, upsample(road, substeps), dt / substeps, es.law, es.rows, es.n_z, D=D, E=E)
    q, qd, qdd = (X[:, ::substeps] for X in (res.q, res.qd, res.qdd))
    Gt = np.swapaxes(G, -1, -2)
    disp, acc = q[..., :3] @ Gt, qdd[..., :3] @ Gt
    n = road.shape[0]

    def shaped(X: NDArray) -> NDArray:
        return X.reshape(batch + X.shape[1:])

    return Response(
        t=np.arange(n) * dt, q=shaped(q), qd=shaped(qd), qdd=shaped(qdd), disp=shaped(disp), acc=shaped(acc)
    )
