"""The normal equations of a long record, accumulated block by block (issue 26): no (R, D) Jacobian is ever held.

Least squares on a linearised residual needs only H = J'J (D, D), g = J'r (D,) and r'r. A record of 60 000 samples
x 16 channels x 9 unknowns has a Jacobian of 69 MB (and the optimizer's copies of it); the same numbers are sums over
the record's samples, which `Gram` takes a block of rows at a time, channel by channel.

With each channel's constant offset profiled out (the residual loses its mean over the channel's samples, and so do
the Jacobian's columns), the sums are centred co-moments: Chan, Golub and LeVeque's pairwise merge of each block's
own centred sums (the block's mean removed before its products, then the shift between the means added as
n_a n_b / n (mean_a - mean_b)(mean_a - mean_b)'), which keeps the precision that the one-pass form
sum(v v') - n mean mean' loses when a channel's mean is large beside its spread.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


class Gram:
    """Per-channel sums of the outer products v v' of rows v (width,) given in blocks (b, k, width), over each
    channel's observed rows; centred on each channel's mean over them when `centred` (the offsets profiled)."""

    def __init__(self, channels: int, width: int, centred: bool):
        self.centred = centred
        self.count = np.zeros(channels)  # observed rows so far, per channel
        self.mean = np.zeros((channels, width))  # their mean (centred only)
        self.sums = np.zeros((channels, width, width))  # sum of (v - mean)(v - mean)' (centred) or v v'

    def add(self, V: NDArray, mask: NDArray | None = None) -> None:
        """Rows V (b, k, width) of the k channels, `mask` (b, k) bool the observed ones (None: all)."""
        b = V.shape[0]
        w = np.ones(V.shape[:2]) if mask is None else np.asarray(mask, dtype=float)
        nb = w.sum(axis=0)  # (k,)
        if self.centred:
            mb = np.einsum("tk,tki->ki", w, V) / np.maximum(nb, 1.0)[:, None]
            Vc = (V - mb) * w[..., None]  # the block's own mean removed, unobserved rows zero
        else:
            Vc = V * w[..., None] if mask is not None else V
        cols = np.ascontiguousarray(Vc.transpose(1, 2, 0))  # (k, width, b)
        self.sums += cols @ cols.transpose(0, 2, 1)
        if not self.centred or b == 0:
            return
        n = self.count + nb
        share = np.divide(nb, n, out=np.zeros_like(n), where=n > 0)
        delta = mb - self.mean
        self.sums += (self.count * share)[:, None, None] * delta[:, :, None] * delta[:, None, :]
        self.mean += share[:, None] * delta
        self.count = n

    def total(self) -> NDArray:
        """(width, width): the sums over every channel."""
        return self.sums.sum(axis=0)
