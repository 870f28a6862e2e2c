"""Linear lumped-parameter systems driven through springs, dampers and forces: the quarter car, the half car.

    M qdd + C qd + K q = B0 u + B1 ud

u (nu inputs: road heights, an actuator force) is linear between samples (first-order hold), so ud, which drives
a damper between a wheel and the road (the tyre damping), is the hold's slope: piecewise constant, exact. With
p = qd - M^-1 B1 u the state s = [q, p] obeys a proper state equation without ud,

    qd = p + M^-1 B1 u,   pd = -M^-1 K q - M^-1 C p + M^-1 (B0 - C M^-1 B1) u,

which the exact FOH of `sim.modal.linear_foh` integrates (as `scipy.signal.lsim` does a transfer function's
numerator). Displacements read rows of q; accelerations rows of qdd = M^-1 (B0 u + B1 ud - C qd - K q), whose ud
term jumps at each sample under the hold: at a sample it takes the mean of the slopes before and after it (the
central difference of u, one-sided at the ends). The run starts at rest in static equilibrium on the first sample:
K q0 = B0 u0, qd0 = 0.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .modal import linear_foh


def sample_slopes(u: NDArray, dt: float) -> NDArray:
    """ud at the samples (..., n, nu) of a first-order hold: the mean of the slopes either side (one-sided at the
    ends)."""
    return np.gradient(u, dt, axis=-2)


def lumped_outputs(
    M: NDArray, C: NDArray, K: NDArray, B0: NDArray, B1: NDArray, u: NDArray, dt: float, Sq: NDArray, Sa: NDArray
) -> tuple[NDArray, NDArray]:
    """Displacement outputs Sq q (P, n, kd) and acceleration outputs Sa qdd (P, n, ka) of P systems.

    M, C, K (P, d, d); B0, B1 (P, d, nu); u (n, nu) one input for all or (P, n, nu); Sq (P, kd, d), Sa (P, ka, d)."""
    u = np.asarray(u, dtype=float)
    A, Bs, s0, Cy, Dy, Ey = lumped_state_space(M, C, K, B0, B1, u[..., 0, :], Sq, Sa)
    kd = Sq.shape[-2]
    Y = linear_foh(A, Bs, np.ascontiguousarray(s0), u, dt, Cy, Dy)
    acc = Y[..., kd:] + sample_slopes(u, dt) @ np.swapaxes(Ey, -1, -2)
    return Y[..., :kd], acc


def lumped_state_space(
    M: NDArray, C: NDArray, K: NDArray, B0: NDArray, B1: NDArray, u0: NDArray, Sq: NDArray, Sa: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:
    """The state equation of P systems (module docstring): A (P, 2d, 2d), Bs (P, 2d, nu), the start s0 (P, 2d) at
    rest on the first input u0 ((nu,) or (P, nu)), the outputs [Sq q, Sa qdd] = Cy s + Dy u + Ey ud: Cy (P, k, 2d),
    Dy (P, k, nu), and Ey (P, ka, nu) (accelerations only) on the input's slope."""
    P, d = M.shape[0], M.shape[-1]
    Minv = np.linalg.inv(M)
    MB1 = Minv @ B1
    Ak, Ac = -Minv @ K, -Minv @ C
    A = np.zeros((P, 2 * d, 2 * d))
    A[:, :d, d:] = np.eye(d)
    A[:, d:, :d] = Ak
    A[:, d:, d:] = Ac
    Bu = Minv @ (B0 - C @ MB1)
    Bs = np.concatenate([MB1, Bu], axis=1)
    q0 = np.linalg.solve(K, (B0 @ u0[..., :, None]))[..., 0]
    s0 = np.concatenate([np.broadcast_to(q0, (P, d)), -(MB1 @ u0[..., :, None])[..., 0]], axis=1)
    kd = Sq.shape[-2]
    Cy = np.concatenate([np.concatenate([Sq, np.zeros_like(Sq)], axis=-1), Sa @ np.concatenate([Ak, Ac], -1)], 1)
    Dy = np.concatenate([np.zeros((P, kd, B0.shape[-1])), Sa @ Bu], axis=1)
    return A, Bs, s0, Cy, Dy, Sa @ MB1
