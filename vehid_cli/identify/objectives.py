"""Objectives: how far computed responses are from the reference (measured) ones.

* ``f1``, ``f2`` (Gökdağ Eq. 8): sum over the channels of the norm of the error, over the sum of the
  norms of the reference; f1 on displacement channels (body points, wheels, deflections), f2 on accelerations.
* ``wls``: the Gaussian maximum-likelihood objective, residuals weighted by each channel's noise
  standard deviation; reported as chi² per sample (about 1 at the truth when the noise level is right).

Every objective also gives the weighted residual vector r/sigma of its channels, which least-squares
polishing and the Cramér–Rao bound use.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from ..optimizers.normal import Gram

OBJECTIVE_FAMILIES = {"f1": ("disp",), "f2": ("acc",)}
SENSOR_FAMILIES = {"acc": ("acc",), "disp": ("disp",), "both": ("acc", "disp")}


def objective_families(objective: str, sensors: str, present: tuple[str, ...] = ("acc", "disp")) -> tuple[str, ...]:
    """Channel families an objective compares: f1 displacements, f2 accelerations, wls what `sensors` selects of
    the families the layout has (`present`)."""
    wanted = OBJECTIVE_FAMILIES.get(objective) or SENSOR_FAMILIES[sensors]
    return tuple(f for f in wanted if f in present)


SQUARED_AT_ONCE = 1 << 14  # entries of a row squared at a time by `sum_of_squares` (128 kB per row)


def sum_of_squares(r: NDArray) -> NDArray:
    """np.sum(r**2, axis=-1), bit for bit, without its (..., R) array of squares (a long record's residuals are tens
    of MB per copy). NumPy adds a row pairwise: above 128 entries it splits it at half its length rounded down to a
    multiple of 8 and adds the two halves' sums; the squares are made here one such subtree at a time and the
    subtrees added in NumPy's order."""
    n = r.shape[-1]
    if n <= SQUARED_AT_ONCE:
        return np.add.reduce(np.square(r), axis=-1)
    half = n // 2
    half -= half % 8
    return sum_of_squares(r[..., :half]) + sum_of_squares(r[..., half:])


def mean_square(r: NDArray) -> NDArray:
    """np.mean(r**2, axis=-1), bit for bit, without the array of squares (`sum_of_squares`)."""
    return sum_of_squares(r) / r.shape[-1]


GATHER_ROWS = 4096  # time samples of an error gathered at a time by `_gather`


def _gather(r: NDArray, mask: NDArray, out: NDArray) -> None:
    """out (..., m) = r[..., mask]: r (..., n, k) at the True entries of `mask` (n, k), time-major, GATHER_ROWS
    samples at a time: no index array of the record's size, and a strided r (an error made over a simulation's
    columns) never flattened whole."""
    at = 0
    for i0 in range(0, r.shape[-2], GATHER_ROWS):
        part = r[..., i0 : i0 + GATHER_ROWS, :][..., mask[i0 : i0 + GATHER_ROWS]]
        out[..., at : at + part.shape[-1]] = part
        at += part.shape[-1]


def _placed(mask: NDArray | None, part: NDArray, shape: tuple[int, ...]) -> NDArray:
    """(n, k) bool: `part` (one flag per entry of a family, in the residuals' time-major order) at the entries' places,
    the True ones of `mask` (None: every sample); bool arrays only, no index array of the record's size."""
    if mask is None:
        return part.reshape(shape).copy()
    out = np.zeros(shape, dtype=bool)
    out[mask] = part  # a boolean index assigns in C order: time-major, the entries' order
    return out


@dataclass(frozen=True)
class Objective:
    """An objective bound to its reference data: costs and weighted residuals of a batch of simulated channels.

    `observed` marks the samples each channel was measured at (a slow channel on a faster grid; None: all);
    with `offsets`, each channel carries an unknown constant offset, profiled out: the residual's mean over the
    channel's samples is removed (the least-squares offset), in the costs and the residuals alike."""

    name: str  # f1, f2 or wls
    reference: Mapping[str, NDArray]  # family -> (n, k) measured channels
    sigma: Mapping[str, NDArray]  # family -> (k,) noise standard deviation per channel
    observed: Mapping[str, NDArray] | None = None  # family -> (n, k) bool
    offsets: bool = False

    @property
    def families(self) -> tuple[str, ...]:
        return tuple(self.reference)

    @cached_property
    def _masks(self) -> dict[str, NDArray]:
        """family -> (n, k) bool: the observed entries of the families some of whose samples are not (a mask that
        is all True is left out: every sample is an entry). Masks, not flat indices: a long record's indices would
        be 8 bytes an entry, held for the whole fit."""
        return {f: m for f, m in (self.observed or {}).items() if not m.all()}

    def whole(self, family: str) -> bool:
        """Whether every sample of every channel of `family` is a residual entry (`entries` is None), without
        making the entries' indices."""
        return family not in self._masks

    def entries(self, family: str) -> NDArray | None:
        """Flat indices (time-major, into the family's (n, k) block) of the residual entries of `family`, in the
        residual vector's order; None when every sample of every channel is one (`whole`). Made at each call."""
        return None if self.whole(family) else np.flatnonzero(self._masks[family])

    def sample_times(self) -> NDArray:
        """(R,) the time sample (row of the reference) of each weighted residual entry, in `residuals`' order."""
        parts = []
        for family, ref in self.reference.items():
            n, k = ref.shape[-2:]
            flat = self.entries(family)
            parts.append((np.arange(n * k) if flat is None else flat) // k)
        return np.concatenate(parts) if parts else np.zeros(0, dtype=int)

    def entry_channels(self) -> NDArray:
        """(R,) the channel of each weighted residual entry, in `residuals`' order: channels numbered family by
        family in the reference's order, column by column."""
        parts, first = [], 0
        for family, ref in self.reference.items():
            n, k = ref.shape[-2:]
            flat = self.entries(family)
            parts.append(first + (np.arange(n * k) if flat is None else flat) % k)
            first += k
        return np.concatenate(parts) if parts else np.zeros(0, dtype=int)

    def project(self, family: str, d: NDArray) -> NDArray:
        """d (..., n, k) without what the profiled offsets absorb (its per-channel mean over the observed samples),
        in place; d itself without offsets. The residual's linear response to a change of the model's output."""
        return self._centre(family, d) if self.offsets else d

    @property
    def size(self) -> int:
        """R: the number of weighted residuals."""
        return sum(self._sizes.values())

    @cached_property
    def _sizes(self) -> dict[str, int]:
        """family -> its number of weighted residuals (its observed entries)."""
        return {f: int(np.count_nonzero(self._masks[f])) if f in self._masks else ref.shape[-2] * ref.shape[-1]
                for f, ref in self.reference.items()}  # fmt: skip

    def error(self, family: str, sim: NDArray, overwrite: bool = False) -> NDArray:
        """ref - sim (..., n, k), without its per-channel mean over the observed samples when offsets are profiled;
        written over `sim` with `overwrite` (the caller's simulation, not read again: no third copy of a record)."""
        d = np.subtract(self.reference[family], sim, out=sim) if overwrite else self.reference[family] - sim
        return self._centre(family, d) if self.offsets else d

    def _centre(self, family: str, d: NDArray) -> NDArray:
        """d (..., n, k) without each channel's mean over its observed samples, in place (d is returned)."""
        if self.observed is None:
            d -= np.mean(d, axis=-2, keepdims=True)
            return d
        # summed where observed: the same sums as of d * m, bit for bit, without a product the size of d
        d -= np.sum(d, axis=-2, keepdims=True, where=self.observed[family]) / self._counts[family]
        return d

    @cached_property
    def _counts(self) -> dict[str, NDArray]:
        """(k,) the number of observed samples of each channel, per family (counted once, not per evaluation)."""
        return {f: np.sum(m, axis=0) for f, m in (self.observed or {}).items()}

    def _norms(self, family: str, d: NDArray) -> NDArray:
        """Norm over time of each channel (..., k), over the observed samples only."""
        if self.observed is not None:
            d = d * self.observed[family]
        return np.linalg.norm(d, axis=-2)

    def costs(self, outputs: Mapping[str, NDArray]) -> NDArray:
        """Cost of each simulated set of channels in the batch (...,); `outputs`: family -> (..., n, k)."""
        if self.name == "wls":
            return mean_square(self.residuals(outputs))
        return self._eq8(outputs)

    def parts(self, outputs: Mapping[str, NDArray]) -> tuple[NDArray, NDArray]:
        """Numerator and denominator of the cost (wls: sum of squared residuals and their count): several runs'
        costs combine as the sum of numerators over the sum of denominators."""
        if self.name == "wls":
            return sum_of_squares(self.residuals(outputs)), np.asarray(float(self.size))
        return self._eq8_parts(outputs)

    def _eq8_parts(self, outputs: Mapping[str, NDArray]) -> tuple[NDArray, NDArray]:
        num = 0.0
        den = 0.0
        for family, ref in self.reference.items():
            num = num + np.sum(self._norms(family, self.error(family, outputs[family])), axis=-1)
            den = den + np.sum(self._norms(family, self._centre(family, ref.copy()) if self.offsets else ref))
        return num, den

    def _eq8(self, outputs: Mapping[str, NDArray]) -> NDArray:
        num, den = self._eq8_parts(outputs)
        return num / den

    def residuals(
        self, outputs: Mapping[str, NDArray], out: NDArray | None = None, entries: NDArray | None = None,
        overwrite: bool = False,
    ) -> NDArray:  # fmt: skip
        """Weighted residuals (ref - sim) / sigma of all observed channel samples, flattened (..., R), each family's
        written straight into its columns (no list of parts concatenated: a long record's residuals are tens of MB
        per copy); into `out` (..., R) when given (a batch's rows, `task.chunked_residuals`), which is returned.
        With `entries` (increasing indices into the R entries), only those, (..., entries.size): a long record's
        batch on its kept entries (`task.kept_residuals`), the same numbers as the whole vector's. With `overwrite`
        the errors are made in the outputs' arrays (a caller done with its simulation)."""
        first = at = 0
        for family in self.reference:
            r = self.error(family, outputs[family], overwrite)  # (..., n, k); strided when made over the outputs
            r /= self.sigma[family]  # in place
            mask, size = self._masks.get(family), self._sizes[family]
            width = size
            if entries is not None:  # this family's share of the entries, as a mask of its (n, k) block
                local = entries[np.searchsorted(entries, first) : np.searchsorted(entries, first + size)] - first
                chosen = np.zeros(size, dtype=bool)
                chosen[local] = True
                mask, width = _placed(mask, chosen, r.shape[-2:]), local.size
            if out is None:
                out = np.empty(r.shape[:-2] + (self.size if entries is None else entries.size,))
            if mask is None:  # through an (..., n, k) view of out's columns (splitting the last axis: always a view)
                out[..., at : at + width].reshape(r.shape)[...] = r
            else:
                _gather(r, mask, out[..., at : at + width])
            first += size
            at += width
        return out if out is not None else np.zeros(0)

    def residual_jacobian(self, sens: Mapping[str, NDArray]) -> NDArray:
        """(R, D) the weighted residuals' derivatives from the model channels' derivatives `sens` (family -> (n, k, D)):
        -(d sim) / sigma, without what the profiled offsets absorb, at the observed entries, in `residuals`' order,
        each family's rows written straight into the result (a long record's Jacobian is tens of MB per copy)."""
        out, first = None, 0
        for family in self.reference:
            s = np.asarray(sens[family], dtype=float)  # (n, k, D), possibly a view of a larger array
            n, k, D = s.shape
            neg = -np.asarray(self.sigma[family], dtype=float)
            if out is None:
                out = np.empty((self.size, D))
            mean = np.zeros((k, D)) if self.offsets else None
            m = None if self.observed is None else np.asarray(self.observed[family], dtype=float)
            for c in range(k if self.offsets else 0):  # the residual's mean over each channel's samples is
                dc = s[:, c] / neg[c]  # profiled out: so is its derivative (channel by channel, (n, D) at a time)
                mean[c] = dc.mean(axis=0) if m is None else np.sum(dc * m[:, c, None], axis=0) / np.sum(m[:, c])
            keep = self.entries(family)
            size = n * k if keep is None else keep.size
            block = out[first : first + size]
            if keep is None:  # rows time-major, like the residuals
                rows = block.reshape(n, k, D)
                rows[...] = s  # copied, then divided as rows of k D: NumPy's loop over rows of D was twice as slow
                np.divide(rows.reshape(n, k * D), np.repeat(neg, D), out=rows.reshape(n, k * D))
                if mean is not None:
                    rows -= mean
            else:
                at, channel = np.divmod(keep, k)
                for c in range(k):
                    where = np.flatnonzero(channel == c)
                    part = s[at[where], c] / neg[c]
                    if mean is not None:
                        part -= mean[c]
                    block[where] = part
            first += size
        return out if out is not None else np.zeros((0, 0))

    def kept_masks(self, entries: NDArray | None = None) -> dict[str, NDArray] | None:
        """family -> (n, k) bool: the entries summed (the observed samples, or `entries` of them, increasing indices
        into the residual vector); None: every sample. Made of bool arrays only (no index array of the record's size
        beside the caller's `entries`)."""
        if entries is None and self.observed is None:
            return None
        chosen = None
        if entries is not None:
            chosen = np.zeros(self.size, dtype=bool)
            chosen[entries] = True
        out, first = {}, 0
        for family, ref in self.reference.items():
            size = self._sizes[family]
            part = np.ones(size, dtype=bool) if chosen is None else chosen[first : first + size]
            out[family] = _placed(self._masks.get(family), part, ref.shape[-2:])
            first += size
        return out

    def normal_sums(self, dim: int, entries: NDArray | None = None) -> NormalSums | None:
        """An accumulator of `residual_jacobian`'s J'J and J'r over `dim` unknowns, a block of samples at a time (the
        sink of `Experiment.exact_sensitivities`): a long record's normal equations without its (R, D) Jacobian; over
        the residual entries `entries` only (increasing; diagnose's kept samples) where given. None for `entries` with
        profiled offsets (their means are over every observed sample: not these sums)."""
        if entries is not None and self.offsets:
            return None
        return NormalSums(self, dim, self.kept_masks(entries) if entries is not None else None)

    def costs_and_residuals(self, outputs: Mapping[str, NDArray], overwrite: bool = False) -> tuple[NDArray, NDArray]:
        """Both from one simulation (the wls residuals computed once); with `overwrite` a wls objective makes its
        errors in the outputs' arrays (a caller done with them; Eq. 8 reads them again)."""
        wls = self.name == "wls"
        residuals = self.residuals(outputs, overwrite=overwrite and wls)
        costs = mean_square(residuals) if wls else self._eq8(outputs)
        return costs, residuals


class NormalSums:
    """J'J (D, D) and J'r (D,) of an objective's weighted residuals r = (ref - sim) / sigma and their Jacobian
    J = -(d sim) / sigma (`Objective.residual_jacobian`), summed over the observed samples block by block; with
    profiled offsets both lose each channel's mean (centred sums, `optimizers.normal.Gram`), as r and J do."""

    def __init__(self, objective: Objective, dim: int, kept: dict[str, NDArray] | None = None):
        self.objective = objective
        self.kept = kept  # family -> (n, k) bool: the entries summed (None: the observed ones)
        self.grams = {f: Gram(ref.shape[-1], dim + 1, objective.offsets) for f, ref in objective.reference.items()}

    def __call__(self, k0: int, out: Mapping[str, NDArray], sens: Mapping[str, NDArray]) -> None:
        """One block of samples from k0: the model's channels `out` (family -> (b, k)) and derivatives `sens`
        (family -> (b, k, D))."""
        obj = self.objective
        for family, gram in self.grams.items():
            s = sens[family]
            b = s.shape[0]
            sigma = np.asarray(obj.sigma[family], dtype=float)
            V = np.empty(s.shape[:2] + (s.shape[2] + 1,))  # [J row, r] per sample and channel
            np.divide(s, -sigma[:, None], out=V[..., :-1])
            np.divide(obj.reference[family][k0 : k0 + b] - out[family], sigma, out=V[..., -1])
            mask = obj.observed if self.kept is None else self.kept
            gram.add(V, None if mask is None else mask[family][k0 : k0 + b])

    def result(self) -> tuple[NDArray, NDArray]:
        """H = J'J (D, D) and g = J'r (D,) over every block given."""
        S = sum(g.total() for g in self.grams.values())
        return S[:-1, :-1], S[:-1, -1]
