"""The fitted car's linear part (M, C, K) as a map from strut-force histories to the layout's channels: one exact
first-order-hold recursion for many input histories at once, their responses weighted by the task's sigma and laid
out like the objective's residual (observed samples only, each channel's mean removed when offsets are profiled).

Forces are in the kernel's convention: f at the 4 corners enters as M qdd + C qd + K q + D' f = B y, D the strut
deflection from q.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..models.fullcar import N_CORNERS, N_DOF
from ..sim.modal import foh_discretisation, propagate
from ..sim.nonlinear import fullcar_struts

if TYPE_CHECKING:  # the fit's types only
    from .psplines import Basis, PenalisedFit


@dataclass(frozen=True)
class LinearCar:
    """The fitted car's linear part, discretised for strut-force inputs u (4 corners) with a first-order hold,
    with the output rows of the layout's channels."""

    Phi: NDArray
    G1: NDArray
    G2: NDArray
    out_s: dict[str, NDArray]  # family -> (k, 14): the family's channels from the state
    out_u: dict[str, NDArray]  # family -> (k, 4): direct feed-through of the strut forces
    D: NDArray  # (4, 7) strut deflection from q


def _output_rows(layout, family: str, points: NDArray) -> tuple[NDArray, NDArray]:
    """(k, 3) body rows and (k, 4) wheel rows giving each channel of `family` from the body coordinates
    (x_b, phi, theta) and the wheel hops (or their accelerations): a body sensor reads its point's row of `points`
    (Layout.points, (nb, 3)), a wheel sensor its wheel, a deflection sensor the point above its corner minus the
    wheel."""
    index = {pt: i for i, pt in enumerate(layout._points)}
    sensors = layout.of(family)
    body = np.zeros((len(sensors), 3))
    wheel = np.zeros((len(sensors), N_CORNERS))
    for j, s in enumerate(sensors):
        if s.point is not None:
            body[j] = points[index[s.point]]
        if s.kind.startswith("wheel"):
            wheel[j, s.corner - 1] = 1.0
        elif s.kind == "deflection":
            wheel[j, s.corner - 1] = -1.0
    return body, wheel


def linear_car(mats, dt: float, layout, points: NDArray) -> LinearCar:
    """The car `mats` (one set of matrices) discretised at dt [s], its outputs the channels of `layout` with body
    point rows `points` (Layout.points of the car, (nb, 3); the paper's layout: the rows of G)."""
    A, _ = mats.state_space()
    D = fullcar_struts(mats)
    Minv = np.linalg.inv(mats.M)
    Bf = np.zeros((2 * N_DOF, N_CORNERS))
    Bf[N_DOF:, :] = -Minv @ D.T  # generalised force -D' f
    Phi, G1, G2 = foh_discretisation(A, Bf, dt)
    out_s, out_u = {}, {}
    for family in layout.families:
        body, wheel = _output_rows(layout, family, points)
        if family == "acc":  # accelerations: the rows of qdd = A_qdd s + B_qdd f
            out_s[family] = body @ A[N_DOF : N_DOF + 3, :] + wheel @ A[N_DOF + 3 :, :]
            out_u[family] = body @ Bf[N_DOF : N_DOF + 3, :] + wheel @ Bf[N_DOF + 3 :, :]
        else:  # displacements: the rows of q
            rows = np.zeros((body.shape[0], 2 * N_DOF))
            rows[:, :3], rows[:, 3:N_DOF] = body, wheel
            out_s[family] = rows
            out_u[family] = np.zeros((body.shape[0], N_CORNERS))
    return LinearCar(Phi, G1, G2, out_s, out_u, D)


def car_at(exp, values: dict[str, float], dt: float) -> LinearCar:
    """The linear car `values` at dt [s] with the outputs of the experiment's layout."""
    layout = exp.layout
    return linear_car(exp.matrices(values), dt, layout, layout.points(exp.parameters(values)))


def response_columns(
    objective, car: LinearCar, U: NDArray, sigma: dict[str, NDArray], keep: NDArray | None = None, first: int = 0
) -> NDArray:
    """The weighted residual entries (the objective's layout: family by family, time-major, observed entries only)
    that the K input histories U (n, 4, K) explain, (R, K): each family's channels' responses over its `sigma`,
    without what the profiled offsets absorb. The states are made a block of time at a time (`responses_blocks`)
    and each family's rows written straight into the result: a long window's states (n, 14, K) are not held.

    With `keep` (R,) bool: only the kept rows, in columns first: of a new (keep.sum(), first + K) array whose first
    `first` columns are the caller's to fill (the missing force's fit matrix [J | S[keep]]); written block by block
    without the (R, K) array when no offsets are profiled and every family's entries are whole (else that array is
    made and its kept rows copied). The same numbers either way."""
    n, K = U.shape[0], U.shape[2]
    direct = keep is not None and not objective.offsets and all(objective.whole(f) for f in sigma)
    if keep is not None and not direct:
        S = response_columns(objective, car, U, sigma)
        A = np.empty((int(np.count_nonzero(keep)), first + K))
        rows = np.flatnonzero(keep)
        for start in range(0, rows.size, COPY_ROWS):
            A[start : start + COPY_ROWS, first:] = S[rows[start : start + COPY_ROWS]]
        return A
    entries = {f: objective.entries(f) for f in sigma}  # each family's entries' indices (None: whole), made once
    sizes = {f: n * car.out_s[f].shape[0] if rows is None else rows.size for f, rows in entries.items()}
    if direct:
        A = np.empty((int(np.count_nonzero(keep)), first + K))
        for rows, Y in _kept_rows(car, U, sigma, keep):
            A[rows, first:] = Y
        return A
    S = np.empty((sum(sizes.values()), K))
    Ys, first = {}, 0
    for f in sigma:  # each family's (n, k, K) responses: a view of its rows of S when every entry is kept
        k = car.out_s[f].shape[0]
        Ys[f] = S[first : first + sizes[f]].reshape(n, k, K) if entries[f] is None else np.empty((n, k, K))
        first += sizes[f]
    for k0, s in responses_blocks(car, U):
        b = s.shape[0]
        for f, sg in sigma.items():
            Ys[f][k0 : k0 + b] = _weighted(car, f, s, U[k0 : k0 + b], sg)
    first = 0
    for f in sigma:
        Y = Ys.pop(f)
        if objective.offsets:
            objective.project(f, np.moveaxis(Y, -1, 0))  # in place, through the (K, n, k) view
        rows = entries.pop(f)
        if rows is not None:
            S[first : first + sizes[f]] = Y.reshape(-1, K)[rows]
        first += sizes[f]
    return S


def fit_matrix(objective, car: LinearCar, U: NDArray, sigma: dict[str, NDArray], keep: NDArray, J: NDArray) -> NDArray:
    """The missing force's fit matrix A = [J | S[keep]] (keep.sum(), p + K): the caller's p columns J (keep.sum(), p)
    first, then the kept rows of the responses (`response_columns` with `keep`)."""
    p = J.shape[1]
    A = response_columns(objective, car, U, sigma, keep, p)
    A[:, :p] = J
    return A


def response_gram(
    objective, car: LinearCar, U: NDArray, sigma: dict[str, NDArray], keep: NDArray, J: NDArray, r: NDArray
) -> tuple[NDArray, NDArray]:
    """A'A (p + K, p + K) and A'r (p + K,) of the missing force's fit matrix A = [J | S[keep]] (`response_columns`
    with `keep` and `first` = p, its first p columns J (keep.sum(), p)) and the kept residual r, without A: summed
    block by block when `response_columns` writes it so (no offsets, every family's entries whole; else A is made
    and reduced). A long window's A is 15 MB (30 400 kept entries x 61 columns); the same sums to round-off."""
    p = J.shape[1]
    direct = not objective.offsets and all(objective.whole(f) for f in sigma)
    if not direct:
        A = fit_matrix(objective, car, U, sigma, keep, J)
        return A.T @ A, A.T @ r
    K = U.shape[2]
    G, g = np.zeros((p + K, p + K)), np.zeros(p + K)
    for rows, Y in _kept_rows(car, U, sigma, keep):  # rows: consecutive rows of A
        a = np.empty((rows.size, p + K))
        a[:, :p] = J[rows[0] : rows[-1] + 1]
        a[:, p:] = Y
        G += a.T @ a
        g += a.T @ r[rows[0] : rows[-1] + 1]
    return G, g


def _kept_rows(
    car: LinearCar, U: NDArray, sigma: dict[str, NDArray], keep: NDArray
) -> Iterator[tuple[NDArray, NDArray]]:
    """The kept entries' weighted responses of the fit matrix, a block of samples and a family at a time, where every
    family's entries are whole and no offset is profiled: (the rows of the fit matrix they fill (m,), responses
    (m, K)); blocks with no kept entry are skipped. What `response_columns` writes and `response_gram` sums."""
    n, K = U.shape[0], U.shape[2]
    sizes = [n * car.out_s[f].shape[0] for f in sigma]
    offsets = dict(zip(sigma, np.cumsum([0, *sizes])[:-1], strict=True))
    at = np.cumsum(keep) - 1  # the row of the fit matrix of each kept entry
    for k0, s in responses_blocks(car, U):
        b = s.shape[0]
        for f, sg in sigma.items():
            k = car.out_s[f].shape[0]
            lo = offsets[f] + k0 * k
            kept = keep[lo : lo + b * k]
            if kept.any():
                yield at[lo : lo + b * k][kept], _weighted(car, f, s, U[k0 : k0 + b], sg).reshape(-1, K)[kept]


def _weighted(car: LinearCar, family: str, s: NDArray, U: NDArray, sigma: NDArray) -> NDArray:
    """A block's responses (b, k, K) of a family's channels over their sigma, from its states s (b, 14, K) and input
    histories U (b, 4, K) (one expression for both of `response_columns`' paths: the same numbers)."""
    return (car.out_s[family] @ s + car.out_u[family] @ U) / sigma[None, :, None]


def responses(car: LinearCar, U: NDArray) -> NDArray:
    """States (n, 14, K) of the car at rest driven by K strut-force histories U (n, 4, K), one recursion."""
    n = U.shape[0]
    s = np.empty((n, 2 * N_DOF, U.shape[2]))
    s[0] = 0.0
    np.matmul(car.G1, U[:-1], out=s[1:])
    s[1:] += car.G2 @ np.diff(U, axis=0)
    propagate(car.Phi, s)
    return s


COPY_ROWS = 8192  # rows of the responses copied into the fit's matrix at a time (`response_columns` with keep)
RESPONSE_BLOCK = 256  # samples of states `responses_blocks` makes at a time: 256 x 14 x 50 inputs, 1.4 MB


def responses_blocks(car: LinearCar, U: NDArray, block: int = RESPONSE_BLOCK) -> Iterator[tuple[int, NDArray]]:
    """`responses` in time blocks: yields (first sample, states (b, 14, K)), the recursion carried from each block
    to the next, the same numbers as one call (a last block of one sample joins the one before)."""
    n = U.shape[0]
    starts = list(range(0, n, max(1, block)))
    if len(starts) > 1 and n - starts[-1] < 2:
        starts.pop()
    Phi, prev = car.Phi, None
    for k0, k1 in zip(starts, [*starts[1:], n], strict=True):
        s = np.empty((k1 - k0, 2 * N_DOF, U.shape[2]))
        if prev is None:
            s[0] = 0.0
            np.matmul(car.G1, U[: k1 - 1], out=s[1:])
            s[1:] += car.G2 @ np.diff(U[:k1], axis=0)
        else:
            np.matmul(car.G1, U[k0 - 1 : k1 - 1], out=s)
            s += car.G2 @ np.diff(U[k0 - 1 : k1], axis=0)
            step = np.stack([prev, s[0]])
            propagate(Phi, step)  # the step from the last block's last sample, as one recursion takes it
            s[0] = step[1]
        propagate(Phi, s)
        prev = s[-1]
        yield k0, s


@dataclass(frozen=True)
class ForceFit:
    """The force and the unknowns' re-fit on one trajectory d, v (n, 4): the bases, their input histories U, the
    kept columns A = [J | S] (the p nuisance columns first; None where the fit was made from their sums alone),
    their normal equations AtA, Atr, the kept residual rk and the penalised solution."""

    d: NDArray
    v: NDArray
    bases: tuple[Basis, ...]
    U: NDArray
    A: NDArray | None  # None when above FIT_GRAM_BYTES: summed, not held
    AtA: NDArray
    Atr: NDArray
    rk: NDArray
    sol: PenalisedFit
    p: int

    def rss(self, coef: NDArray) -> float:
        """|r - A coef|² (from the normal equations when A is not held)."""
        if self.A is not None:
            return float(np.sum((self.rk - self.A @ coef) ** 2))
        return max(float(self.rk @ self.rk) - 2.0 * float(coef @ self.Atr) + float(coef @ self.AtA @ coef), 0.0)

    def explained(self, sl: slice, line: int | None) -> float:
        """The mean square over the R entries of the curve's columns' share A[:, sl] coef[sl] of the residual,
        less its projection on the unknown's column A[:, line] (when given, the part that unknown absorbs)."""
        coef = self.sol.coef
        if self.A is not None:
            contrib = self.A[:, sl] @ coef[sl]
            if line is not None:
                own = self.A[:, line]
                contrib = contrib - own * float(own @ contrib) / max(float(own @ own), 1e-300)
            return float(np.mean(contrib**2))
        G = self.AtA
        square = float(coef[sl] @ G[sl, sl] @ coef[sl])
        if line is not None:
            square -= float(G[line, sl] @ coef[sl]) ** 2 / max(float(G[line, line]), 1e-300)
        return max(square, 0.0) / self.rk.size

    @property
    def theta(self) -> NDArray:
        """The basis coefficients of the force."""
        return self.sol.coef[self.p :]

    @property
    def dx(self) -> NDArray:
        """The unknowns' re-fit."""
        return self.sol.coef[: self.p]
