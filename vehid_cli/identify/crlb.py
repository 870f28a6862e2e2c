"""The Cramér–Rao bound of an experiment: how well any unbiased estimator can identify the unknowns.

For white Gaussian noise of standard deviation sigma_c on channel c, the Fisher information of the
unknowns theta is F = sum_c sum_t (dz_c(t)/dtheta)(dz_c(t)/dtheta)' / sigma_c². Its inverse bounds the
covariance of any unbiased estimate. Sensitivities come from central differences of the batched
simulator (all 2D perturbed cars in one call). Everything is reported relative to theta, as RE is.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..optimizers.normal import Gram
from ..sim.sensitivity import central_points
from .experiment import Experiment

UNIDENTIFIABLE_RE_SD = 50.0  # % — a bound this wide means the sensors cannot pin the parameter down
NEAR_SINGULAR = 1e-10  # smallest/largest eigenvalue of the correlation-scaled information


@dataclass(frozen=True)
class CramerRao:
    """The bound at parameter values `values` for the noise `sigma` of the channels used."""

    names: tuple[str, ...]
    values: NDArray  # (D,) where the bound is evaluated (the truth, or the nominal car)
    fisher: NDArray  # (D, D) information of the relative parameters theta_j / values_j
    re_sd_percent: NDArray  # (D,) smallest achievable per-run standard deviation of RE [%]
    nre_rms_percent: float  # root-sum-square of re_sd_percent: the NRE RMS an efficient estimator reaches
    identifiable: NDArray  # (D,) bool
    condition: float  # condition number of the correlation-scaled information

    @property
    def sd(self) -> NDArray:
        """Absolute standard deviation bound (D,) in the parameters' units."""
        with np.errstate(invalid="ignore"):  # an unidentifiable parameter (inf) of value 0: nan
            return self.re_sd_percent / 100.0 * np.abs(self.values)

    def unidentifiable(self) -> list[str]:
        return [n for n, ok in zip(self.names, self.identifiable, strict=True) if not ok]

    def widened(self, factor: float) -> CramerRao:
        """The bound with every standard deviation `factor` times wider (the information over factor²): the residual's
        own variance instead of the assumed noise's, when the residual is larger than the noise."""
        return dataclasses.replace(
            self, fisher=self.fisher / factor**2, re_sd_percent=self.re_sd_percent * factor,
            nre_rms_percent=self.nre_rms_percent * factor,
        )  # fmt: skip


def sensitivities(
    experiment: Experiment,
    names: Sequence[str],
    values: NDArray,
    families: Sequence[str],
    rel_step: float = 1e-5,
) -> dict[str, NDArray]:
    """d channel / d (theta_j / values_j) for each family: (n, k, D): the experiment's exact sensitivities when it has
    them there (`exact_sensitivities`, through the same modal solution as the simulation), else central differences
    of the batched simulator."""
    return dict(_sensitivities(experiment, names, values, families, rel_step))


def _sensitivities(
    experiment: Experiment, names: Sequence[str], values: NDArray, families: Sequence[str], rel_step: float
) -> Iterator[tuple[str, NDArray]]:
    """`sensitivities` family by family: each family's array made only when it is asked for (the bound's
    information then holds one family's beside the experiment's own)."""
    values = np.asarray(values, dtype=float)
    exact = getattr(experiment, "exact_sensitivities", None)
    got = exact(names, values) if exact is not None else None
    if got is not None:
        for family in families:
            yield family, got[1][family] * np.abs(values)
        return
    D = values.size
    h = rel_step * np.abs(values)
    X = central_points(values, h)
    outputs = experiment.outputs({n: X[:, j] for j, n in enumerate(names)})
    for family in families:
        z = outputs[family]  # (2D, n, k)
        dz = (z[:D] - z[D:]) / (2 * h[:, None, None])  # (D, n, k) per unit of theta_j
        yield family, np.moveaxis(dz * np.abs(values)[:, None, None], 0, -1)  # per relative change


def weighted_sensitivities(
    experiment: Experiment,
    names: Sequence[str],
    values: NDArray,
    sigma: Mapping[str, NDArray],
    observed: Mapping[str, NDArray] | None = None,
    offsets: bool = False,
    rel_step: float = 1e-5,
) -> dict[str, NDArray]:
    """Sensitivities over the noise, W (n, k, D) per family of `sigma` (family -> (k,)): zero where a channel has no
    sample (`observed`: family -> (n, k) bool; None: all). With `offsets`, each channel has an unknown constant
    offset: its sensitivities lose their mean over the channel's samples, which leaves the information that remains
    once the offsets are estimated too (the Schur complement)."""
    return dict(_weighted(experiment, names, values, sigma, observed, offsets, rel_step))


def _weighted(
    experiment: Experiment, names: Sequence[str], values: NDArray, sigma: Mapping[str, NDArray],
    observed: Mapping[str, NDArray] | None, offsets: bool, rel_step: float,
) -> Iterator[tuple[str, NDArray]]:  # fmt: skip
    """`weighted_sensitivities` family by family."""
    values = np.asarray(values, dtype=float)
    for family, S in _sensitivities(experiment, names, values, list(sigma), rel_step):
        mask = None if observed is None else np.asarray(observed[family], dtype=float)[:, :, None]
        if offsets:
            mean = S.mean(axis=0) if mask is None else (S * mask).sum(axis=0) / mask.sum(axis=0)
            S -= mean[None]  # in place (S is `sensitivities`' own array): a long record's are tens of MB per copy
        S /= np.asarray(sigma[family], dtype=float)[None, :, None]
        if mask is not None:
            S *= mask
        yield family, S


def information(
    experiment: Experiment,
    names: Sequence[str],
    values: NDArray,
    sigma: Mapping[str, NDArray],
    observed: Mapping[str, NDArray] | None = None,
    offsets: bool = False,
    rel_step: float = 1e-5,
) -> NDArray:
    """Fisher information (D, D) of the relative unknowns theta_j / values_j carried by the channels of `sigma`
    (family -> (k,)), counted at their `observed` samples, offsets estimated alongside (`weighted_sensitivities`)."""
    D = np.asarray(values).size
    F = np.zeros((D, D))
    for _, W in _weighted(experiment, names, values, sigma, observed, offsets, rel_step):  # one family at a time
        W = W.reshape(-1, D)
        F += W.T @ W
    return F


def summed_information(
    experiment: Experiment,
    names: Sequence[str],
    values: NDArray,
    sigma: Mapping[str, NDArray],
    observed: Mapping[str, NDArray] | None = None,
    offsets: bool = False,
) -> NDArray | None:
    """`information` from the experiment's exact sensitivities summed a block of samples at a time
    (`exact_sensitivities` with a sink; centred sums with `offsets`, `optimizers.normal.Gram`): a long record's
    information without its (n, k, D) sensitivities. None where the exact sensitivities do not apply."""
    values = np.asarray(values, dtype=float)
    scale = np.abs(values)
    grams = {f: Gram(np.size(s), values.size, offsets) for f, s in sigma.items()}

    def add(k0: int, out: Mapping[str, NDArray], sens: Mapping[str, NDArray]) -> None:
        for family, gram in grams.items():
            V = sens[family] * (scale / np.asarray(sigma[family], dtype=float)[:, None])  # (b, k, D), relative
            gram.add(V, None if observed is None else observed[family][k0 : k0 + V.shape[0]])

    if experiment.exact_sensitivities(names, values, sink=add) is None:
        return None
    return sum(g.total() for g in grams.values())


def cramer_rao(
    experiment: Experiment,
    names: Sequence[str],
    values: NDArray,
    sigma: Mapping[str, NDArray],
    rel_step: float = 1e-5,
    observed: Mapping[str, NDArray] | None = None,
    offsets: bool = False,
) -> CramerRao:
    """The bound for the unknowns `names` at `values`, channels and noise given by `sigma` (family -> (k,)); see
    `information` for `observed` and `offsets`."""
    F = information(experiment, names, values, sigma, observed, offsets, rel_step)
    return bound_from_information(names, values, F)


def bound_from_information(names: Sequence[str], values: NDArray, F: NDArray) -> CramerRao:
    """The bound from the Fisher information F (D, D) of the relative parameters theta_j / values_j."""
    values = np.asarray(values, dtype=float)
    D = values.size
    # A parameter the data carries (next to) no information about has an infinite bound: it is not
    # dropped from the inverse (a pseudo-inverse would silently report a tiny bound for it).
    info = np.diag(F)
    seen = info > NEAR_SINGULAR * max(info.max(), 1e-300)
    identifiable = seen.copy()
    re_sd = np.full(D, np.inf)
    condition = np.inf
    if seen.any():
        Fs = F[np.ix_(seen, seen)]
        scale = np.sqrt(np.diag(Fs))
        corr = Fs / scale[:, None] / scale[None, :]
        eig, vec = np.linalg.eigh(corr)
        condition = float(eig[-1] / max(eig[0], 1e-300)) if seen.all() else np.inf
        weak = eig / eig[-1] < NEAR_SINGULAR
        in_null = np.any(np.abs(vec[:, weak]) > 0.3, axis=1) if weak.any() else np.zeros(seen.sum(), bool)
        cov = np.linalg.pinv(corr, rcond=NEAR_SINGULAR, hermitian=True) / scale[:, None] / scale[None, :]
        sd = 100.0 * np.sqrt(np.clip(np.diag(cov), 0.0, None))
        sd[in_null] = np.inf
        re_sd[seen] = sd
        identifiable[seen] = ~in_null
    identifiable &= re_sd < UNIDENTIFIABLE_RE_SD
    return CramerRao(
        names=tuple(names),
        values=values,
        fisher=F,
        re_sd_percent=re_sd,
        nre_rms_percent=float(np.sqrt(np.sum(re_sd**2))),
        identifiable=identifiable,
        condition=condition,
    )


def cramer_rao_outputs(
    names: Sequence[str],
    values: NDArray,
    simulate: Callable[[NDArray], NDArray],
    sigma: float | NDArray,
    rel_step: float = 1e-5,
) -> CramerRao:
    """The bound of any model observed with white Gaussian noise: `simulate` maps candidates (P, D) to outputs
    (P, m) (e.g. a damper's force on a bench run), `sigma` is the noise standard deviation (scalar or (m,))."""
    values = np.asarray(values, dtype=float)
    D = values.size
    h = rel_step * np.maximum(np.abs(values), 1e-12)
    X = central_points(values, h)
    y = np.asarray(simulate(X), dtype=float)
    S = (y[:D] - y[D:]) / (2 * h[:, None]) * np.abs(values)[:, None]  # (D, m) per relative change
    W = S / np.asarray(sigma, dtype=float)
    return bound_from_information(names, values, W @ W.T)
