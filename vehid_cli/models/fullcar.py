"""The 7-DOF full-car vertical model (Gökdağ 2015, Fig. 1; SPEC section 1), batched over parameter sets.

Coordinates q = [x, phi, theta, x1, x2, x3, x4]: body bounce, roll, pitch, wheel hops, all from static
equilibrium. M, C, K follow from the energies through one geometry matrix G (body point above each
corner from the body coordinates), so the printed matrices of the paper are derived, not typed:

    T = 1/2 qd' M qd
    V = 1/2 sum_i ks_i (G_i q_b - x_i)^2 + 1/2 sum_i kt_i (x_i - y_i)^2 + kR/2 (phi - (x1 - x2)/w)^2
    D = 1/2 sum_i cs_i (G_i qd_b - xd_i)^2

Every function takes parameters as arrays of a common batch shape (scalars for one car), so a whole
population of candidate cars is assembled in one call.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

N_DOF = 7
N_CORNERS = 4
DOF_NAMES = ("bounce", "roll", "pitch", "wheel1", "wheel2", "wheel3", "wheel4")
FRONT = np.array([True, True, False, False])  # corners 1, 2 front; 3, 4 rear
VEHICLE_PARAMETERS = (  # the 16 model parameters (SPEC section 1)
    "m", "mf", "mr", "Ix", "Iy", "a1", "a2", "b1", "b2",
    "kf", "kr", "ktf", "ktr", "kR", "cf", "cr",
)  # fmt: skip


class CarValues(Protocol):
    """What a configured car offers the model: its 16 parameter values, wheelbase L and track w [m]
    (config.Vehicle is one)."""

    L: float
    w: float

    def values(self) -> dict[str, float]: ...


def geometry(a1: ArrayLike, a2: ArrayLike, b1: ArrayLike, b2: ArrayLike) -> NDArray:
    """G (..., 4, 3): vertical displacement of the body point above corner i from [x, phi, theta] (Eq. 7)."""
    a1, a2, b1, b2 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (a1, a2, b1, b2)))
    G = np.empty(a1.shape + (N_CORNERS, 3))  # filled entry by entry (nested stacks had cost a quarter of assemble)
    G[..., :, 0] = 1.0
    G[..., 0, 1], G[..., 0, 2] = b1, -a1  # corner 1: front, side b1
    G[..., 1, 1], G[..., 1, 2] = -b2, -a1  # corner 2: front, side b2
    G[..., 2, 1], G[..., 2, 2] = -b2, a2  # corner 3: rear, side b2
    G[..., 3, 1], G[..., 3, 2] = b1, a2  # corner 4: rear, side b1
    return G


@dataclass(frozen=True)
class FullCarMatrices:
    """M, C, K (..., 7, 7), road input matrix B (..., 7, 4) with M qdd + C qd + K q = B y, and G (..., 4, 3)."""

    M: NDArray
    C: NDArray
    K: NDArray
    B: NDArray
    G: NDArray

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.M.shape[:-2]

    def state_space(self) -> tuple[NDArray, NDArray]:
        """A (..., 14, 14), Bs (..., 14, 4) for s = [q, qd]: sd = A s + Bs y."""
        batch = self.batch_shape
        A = np.zeros(batch + (2 * N_DOF, 2 * N_DOF))
        A[..., :N_DOF, N_DOF:] = np.eye(N_DOF)
        Bs = np.zeros(batch + (2 * N_DOF, N_CORNERS))
        diagonal = np.diagonal(self.M, axis1=-2, axis2=-1)
        if np.count_nonzero(self.M) == np.count_nonzero(diagonal):  # M diagonal (assemble's): rows scaled, the
            inv = (1.0 / diagonal)[..., :, None]  # same numbers as inv(M) @ X (LAPACK inverts a diagonal exactly)
            np.multiply(-inv, self.K, out=A[..., N_DOF:, :N_DOF])
            np.multiply(-inv, self.C, out=A[..., N_DOF:, N_DOF:])
            np.multiply(inv, self.B, out=Bs[..., N_DOF:, :])
            return A, Bs
        Minv = np.linalg.inv(self.M)
        A[..., N_DOF:, :N_DOF] = -Minv @ self.K
        A[..., N_DOF:, N_DOF:] = -Minv @ self.C
        Bs[..., N_DOF:, :] = Minv @ self.B
        return A, Bs

    def natural_frequencies(self) -> NDArray:
        """Undamped natural frequencies (..., 7) [rad/s], ascending, from K v = w^2 M v."""
        # M is diagonal and positive: symmetric scaling keeps the problem symmetric.
        s = 1.0 / np.sqrt(np.diagonal(self.M, axis1=-2, axis2=-1))
        Ks = self.K * s[..., :, None] * s[..., None, :]
        return np.sqrt(np.clip(np.linalg.eigvalsh(Ks), 0.0, None))


def assemble(p: Mapping[str, ArrayLike]) -> FullCarMatrices:
    """Assemble M, C, K, B, G from the 16 parameters (arrays of one batch shape or scalars)."""
    missing = [n for n in VEHICLE_PARAMETERS if n not in p]
    if missing:
        raise KeyError(f"missing vehicle parameters: {missing}")
    arrays = np.broadcast_arrays(*(np.asarray(p[n], dtype=float) for n in VEHICLE_PARAMETERS))
    v = dict(zip(VEHICLE_PARAMETERS, arrays, strict=True))
    batch = v["m"].shape
    G = geometry(v["a1"], v["a2"], v["b1"], v["b2"])

    # Suspension deflection d = D q with D = [G, -I]; tyre deflection x_i - y_i = E q - y with E = [0, I].
    D = np.zeros(batch + (N_CORNERS, N_DOF))
    D[..., :, :3] = G
    D[..., :, 3:] = -np.eye(N_CORNERS)
    E = np.zeros((N_CORNERS, N_DOF))
    E[:, 3:] = np.eye(N_CORNERS)

    def per_corner(front: str, rear: str) -> NDArray:
        return np.stack([v[front], v[front], v[rear], v[rear]], axis=-1)

    ks, cs, kt = per_corner("kf", "kr"), per_corner("cf", "cr"), per_corner("ktf", "ktr")
    Dt = np.swapaxes(D, -1, -2)
    K = Dt @ (ks[..., :, None] * D) + E.T @ (kt[..., :, None] * E)
    C = Dt @ (cs[..., :, None] * D)

    # Front anti-roll bar: kR/2 (phi - (x1 - x2)/w)^2 = kR/2 (r q)^2.
    w = v["b1"] + v["b2"]
    r = np.zeros(batch + (N_DOF,))
    r[..., 1] = 1.0
    r[..., 3] = -1.0 / w
    r[..., 4] = 1.0 / w
    K = K + v["kR"][..., None, None] * r[..., :, None] * r[..., None, :]

    M = np.zeros(batch + (N_DOF, N_DOF))
    for i, name in enumerate(("m", "Ix", "Iy", "mf", "mf", "mr", "mr")):
        M[..., i, i] = v[name]
    B = E.T * kt[..., None, :]  # (..., 7, 4): force kt_i y_i on wheel i
    return FullCarMatrices(M=M, C=C, K=K, B=B, G=G)


def parameter_batch(vehicle: CarValues, values: Mapping[str, ArrayLike] | None = None) -> dict[str, NDArray]:
    """The 16 parameters for a batch of cars: the configured car with some parameters replaced.

    Wheelbase and track stay at their configured values when a1/a2 or b1/b2 change (SPEC section 1):
    the centre of gravity moves, the car does not change size.
    """
    base = vehicle.values()
    values = {k: np.asarray(val, dtype=float) for k, val in (values or {}).items()}
    unknown = set(values) - set(base)
    if unknown:
        raise KeyError(f"not vehicle parameters: {sorted(unknown)}")
    if "a1" in values and "a2" in values:
        raise ValueError("a1 and a2 cannot both vary: the wheelbase is fixed")
    if "b1" in values and "b2" in values:
        raise ValueError("b1 and b2 cannot both vary: the track is fixed")
    out = {k: np.asarray(base[k], dtype=float) for k in base}
    out.update(values)
    L, w = vehicle.L, vehicle.w
    if "a1" in values:
        out["a2"] = L - values["a1"]
    if "a2" in values:
        out["a1"] = L - values["a2"]
    if "b1" in values:
        out["b2"] = w - values["b1"]
    if "b2" in values:
        out["b1"] = w - values["b2"]
    shape = np.broadcast_shapes(*(a.shape for a in out.values()))
    return {k: _read_only(a, shape) for k, a in out.items()}


def _read_only(a: NDArray, shape: tuple[int, ...]) -> NDArray:
    """np.broadcast_to(a, shape) (a read-only array of `shape`), at a fraction of its cost for the two usual cases:
    a scalar (filled) and an array of that shape already (a view); it ran once per parameter per batch."""
    if a.shape == shape:
        out = np.asarray(a).view()  # (L - a1 of one car is a NumPy scalar, not an array)
    elif a.ndim == 0:
        out = np.full(shape, a)
    else:
        return np.broadcast_to(a, shape)
    out.flags.writeable = False
    return out
