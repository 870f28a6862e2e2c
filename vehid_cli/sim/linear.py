"""Time integration of the linear full car, batched over parameter sets.

Integrators, all taking plain arrays so later code can batch and compile them:

* ``exact``: the exact discretisation of M qdd + C qd + K q = B y(t) for a road that is linear between
  samples (first-order hold). With a piecewise-linear road it is exact to round-off; this is also what
  ``scipy.signal.lsim`` assumes. Runs through the compiled modal recursions of ``sim.modal`` (same
  discretisation, mode by mode, 8 cars at a time); ``simulate_columns`` computes only the columns a
  layout reads (the identification's path, several thousand cars per second on one core for 3000 samples:
  ``benchmarks/bench_simulation.py``).
* ``exact-reference``: the same discretisation from one matrix exponential of an augmented matrix and
  a NumPy loop over time: slow, simple, kept as the reference the fast path is tested against.
* ``newmark``: Newmark-beta with average acceleration (gamma = 1/2, beta = 1/4), as in the paper;
  second order, unconditionally stable.

The car starts at rest in static equilibrium on the initial road height: q0 = K^-1 B y0 (zero for a
road that starts at zero).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..models.fullcar import N_DOF, FullCarMatrices
from .modal import column_index, foh_discretisation, modal_columns, modal_foh

Integrator = Literal["exact", "exact-reference", "newmark"]
Column = tuple[str, int]  # a Response field (q, qd, qdd, disp, acc) and the index of its last axis


@dataclass(frozen=True)
class Response:
    """Responses of a batch of cars on one time grid: arrays are (..., n, k) with the batch in front."""

    t: NDArray  # (n,) [s]
    q: NDArray  # (..., n, 7) coordinates [m, rad]
    qd: NDArray  # (..., n, 7) velocities
    qdd: NDArray  # (..., n, 7) accelerations
    disp: NDArray  # (..., n, nb) vertical displacement of the body points (default z1..z4 above the corners) [m]
    acc: NDArray  # (..., n, nb) vertical acceleration of the body points [m/s²]

    @property
    def bounce(self) -> NDArray:
        """Body CG displacement x (..., n) [m]."""
        return self.q[..., 0]

    @property
    def roll(self) -> NDArray:
        """Roll angle phi (..., n) [rad]."""
        return self.q[..., 1]

    @property
    def pitch(self) -> NDArray:
        """Pitch angle theta (..., n) [rad]."""
        return self.q[..., 2]


def simulate(
    mats: FullCarMatrices, road: NDArray, dt: float, integrator: Integrator = "exact", points: NDArray | None = None
) -> Response:
    """Respond to the road (n, 4) [m] sampled every dt [s]: one call for the whole batch of cars. `points`
    (..., nb, 3), rows [1, y, -x], are the body points whose motion `disp` and `acc` give (default the corners',
    mats.G; models.sensors.Layout.points)."""
    road = _checked(road)
    n = road.shape[-2]
    t = np.arange(n) * dt
    if integrator == "exact":
        q, qd, qdd, disp, acc = modal_foh(mats, road, dt, points)
        return Response(t=t, q=q, qd=qd, qdd=qdd, disp=disp, acc=acc)
    if integrator == "exact-reference":
        q, qd, qdd = _exact_foh(mats, road, dt)
    elif integrator == "newmark":
        q, qd, qdd = _newmark(mats, road, dt)
    else:
        raise ValueError(f"unknown integrator {integrator!r}")
    G = mats.G if points is None else np.asarray(points, dtype=float)
    Gt = np.swapaxes(G, -1, -2)[..., None, :, :]  # (..., 1, 3, nb)
    disp = (q[..., None, :3] @ Gt)[..., 0, :]
    acc = (qdd[..., None, :3] @ Gt)[..., 0, :]
    return Response(t=t, q=q, qd=qd, qdd=qdd, disp=disp, acc=acc)


def simulate_columns(
    mats: FullCarMatrices,
    road: NDArray,
    dt: float,
    groups: Sequence[Sequence[Column]],
    integrator: Integrator = "exact",
    points: NDArray | None = None,
) -> list[NDArray]:
    """Some columns of `simulate`'s response, the same numbers: one array (..., n, len(group)) per group of
    (field, index) pairs, e.g. [("acc", 0), ("disp", 2)] for acc[..., 0] and disp[..., 2].

    The exact integrator computes only these (projecting its modal coordinates onto every column of the response
    is most of its work; an identification reads a few channels: models.sensors.Layout.column_groups); the
    other integrators pick them from the whole response."""
    road = _checked(road)
    if integrator == "exact":
        nb = (mats.G if points is None else np.asarray(points)).shape[-2]
        return modal_columns(mats, road, dt, [[column_index(f, i, nb) for f, i in g] for g in groups], points)
    response = simulate(mats, road, dt, integrator, points)
    empty = np.empty(response.q.shape[:-1] + (0,))
    return [np.stack([getattr(response, f)[..., i] for f, i in g], axis=-1) if g else empty for g in groups]


def _checked(road: NDArray) -> NDArray:
    """The road as floats (..., n, 4) [m], or ValueError."""
    road = np.asarray(road, dtype=float)
    if road.ndim < 2 or road.shape[-1] != 4:
        raise ValueError(f"road must be (..., n, 4), got {road.shape}")
    return road


def static_equilibrium(mats: FullCarMatrices, y: NDArray) -> NDArray:
    """q (..., 7) with K q = B y: the car at rest on road heights y (..., 4)."""
    return np.linalg.solve(mats.K, (mats.B @ np.asarray(y, dtype=float)[..., :, None]))[..., 0]


def _exact_foh(mats: FullCarMatrices, road: NDArray, dt: float) -> tuple[NDArray, NDArray, NDArray]:
    A, Bs = mats.state_space()
    Phi, G1, G2 = foh_discretisation(A, Bs, dt)
    batch = np.broadcast_shapes(mats.batch_shape, road.shape[:-2])
    n = road.shape[-2]
    u = np.broadcast_to(road, batch + road.shape[-2:])
    # Input contribution to every step at once, then the homogeneous recursion.
    G1t, G2t = np.swapaxes(G1, -1, -2), np.swapaxes(G2, -1, -2)
    drive = np.matmul(u[..., :-1, :], G1t) + np.matmul(np.diff(u, axis=-2), G2t)  # (..., n-1, 14)
    PhiT = np.broadcast_to(np.swapaxes(Phi, -1, -2), batch + Phi.shape[-2:])
    s = np.empty(batch + (n, 2 * N_DOF))
    s[..., 0, :N_DOF] = static_equilibrium(mats, u[..., 0, :])
    s[..., 0, N_DOF:] = 0.0
    for k in range(n - 1):
        s[..., k + 1, :] = np.matmul(s[..., k, None, :], PhiT)[..., 0, :] + drive[..., k, :]
    sd = np.matmul(s, np.swapaxes(A, -1, -2)) + np.matmul(u, np.swapaxes(Bs, -1, -2))
    return s[..., :N_DOF], s[..., N_DOF:], sd[..., N_DOF:]


def _newmark(
    mats: FullCarMatrices, road: NDArray, dt: float, gamma: float = 0.5, beta: float = 0.25
) -> tuple[NDArray, NDArray, NDArray]:
    """Newmark-beta in incremental-free form; the defaults are the average-acceleration rule."""
    M, C, K = mats.M, mats.C, mats.K
    batch = np.broadcast_shapes(mats.batch_shape, road.shape[:-2])
    n = road.shape[-2]
    u = np.broadcast_to(road, batch + road.shape[-2:])
    F = np.matmul(u, np.swapaxes(mats.B, -1, -2))  # (..., n, 7) road forces
    a0, a1 = 1.0 / (beta * dt * dt), gamma / (beta * dt)
    a2, a3 = 1.0 / (beta * dt), 1.0 / (2 * beta) - 1.0
    a4, a5 = gamma / beta - 1.0, dt * (gamma / (2 * beta) - 1.0)
    Khat_inv_T = np.swapaxes(np.linalg.inv(K + a1 * C + a0 * M), -1, -2)
    MT, CT, KT = (np.swapaxes(X, -1, -2) for X in (M, C, K))
    Minv_T = np.swapaxes(np.linalg.inv(M), -1, -2)

    def rowmul(x: NDArray, XT: NDArray) -> NDArray:
        return np.matmul(x[..., None, :], XT)[..., 0, :]

    q = np.empty(batch + (n, N_DOF))
    v = np.zeros(batch + (n, N_DOF))
    a = np.empty(batch + (n, N_DOF))
    q[..., 0, :] = static_equilibrium(mats, u[..., 0, :])
    a[..., 0, :] = rowmul(F[..., 0, :] - rowmul(q[..., 0, :], KT), Minv_T)
    for k in range(n - 1):
        qk, vk, ak = q[..., k, :], v[..., k, :], a[..., k, :]
        rhs = F[..., k + 1, :] + rowmul(a0 * qk + a2 * vk + a3 * ak, MT) + rowmul(a1 * qk + a4 * vk + a5 * ak, CT)
        qn = rowmul(rhs, Khat_inv_T)
        an = a0 * (qn - qk) - a2 * vk - a3 * ak
        q[..., k + 1, :] = qn
        a[..., k + 1, :] = an
        v[..., k + 1, :] = vk + dt * ((1 - gamma) * ak + gamma * an)
    return q, v, a
