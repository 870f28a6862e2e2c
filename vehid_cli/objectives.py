"""Objectives: how far computed responses are from the reference (measured) ones.

* ``f1``, ``f2`` (Gökdağ Eq. 8): sum over the four channels of the norm of the error, over the sum of the
  norms of the reference; f1 on body-point displacements, f2 on accelerations.
* ``wls``: the Gaussian maximum-likelihood objective, residuals weighted by each channel's noise
  standard deviation; reported as chi² per sample (about 1 at the truth when the noise level is right).

Every objective also gives the weighted residual vector r/sigma of its channels, which least-squares
polishing and the Cramér–Rao bound use.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .sim.linear import Response

OBJECTIVE_FAMILIES = {"f1": ("disp",), "f2": ("acc",)}
SENSOR_FAMILIES = {"acc": ("acc",), "disp": ("disp",), "both": ("acc", "disp")}


def objective_families(objective: str, sensors: str) -> tuple[str, ...]:
    """Response families an objective compares: f1 displacements, f2 accelerations, wls what the sensors give."""
    return OBJECTIVE_FAMILIES.get(objective) or SENSOR_FAMILIES[sensors]


@dataclass(frozen=True)
class Objective:
    """An objective bound to its reference data: costs and weighted residuals of a batch of responses."""

    name: str  # f1, f2 or wls
    reference: Mapping[str, NDArray]  # family -> (n, 4) measured responses
    sigma: Mapping[str, NDArray]  # family -> (4,) noise standard deviation per channel

    @property
    def families(self) -> tuple[str, ...]:
        return tuple(self.reference)

    def costs(self, response: Response) -> NDArray:
        """Cost of each response in the batch (...,)."""
        if self.name == "wls":
            return np.mean(self.residuals(response) ** 2, axis=-1)
        return self._eq8(response)

    def _eq8(self, response: Response) -> NDArray:
        num = 0.0
        den = 0.0
        for family, ref in self.reference.items():
            sim = getattr(response, family)
            num = num + np.sum(np.linalg.norm(ref - sim, axis=-2), axis=-1)
            den = den + np.sum(np.linalg.norm(ref, axis=-2))
        return num / den

    def residuals(self, response: Response) -> NDArray:
        """Weighted residuals (ref - sim) / sigma of all channels, flattened (..., R)."""
        parts = []
        for family, ref in self.reference.items():
            sim = getattr(response, family)
            r = (ref - sim) / self.sigma[family]
            parts.append(r.reshape(r.shape[:-2] + (-1,)))
        return np.concatenate(parts, axis=-1)

    def costs_and_residuals(self, response: Response) -> tuple[NDArray, NDArray]:
        """Both from one simulation (the wls residuals computed once)."""
        residuals = self.residuals(response)
        costs = np.mean(residuals**2, axis=-1) if self.name == "wls" else self._eq8(response)
        return costs, residuals
