"""A forward-difference Jacobian's normal equations summed over a long record in time blocks (issue 26).

The least squares of a long record on the RK4 kernel needs, per step, only the Gram matrix of A = [J r]: J'J, J'r
and r'r (`optimizers/compressed.py`). Held as an array, J is (D, R): 9 unknowns x 360 000 held-in entries of a 60 s
record at 1 kHz are 26 MB, with the chunks of simulated cars in flight beside it (the diagnosis's peak). Here the
centre car and the D perturbed ones are simulated together block by block (the kernel resumes mid-record,
`Experiment.simulate_blocks`), and each block's rows [(r(x + h_j) - r(x)) / h_j for j, r(x)] are added to
`optimizers.normal.Gram` per channel: nothing of the size of the record is made beyond the reference itself. The
measurement chain's corrections a fit carries (a flipped sign, a gain, a swap, an offset, clipped or dropped samples:
each reads only its own samples, `Fault.local`) are applied to each block's channels as to the whole record's.

The entries are the objective's (each channel's observed samples), or some of them (`entries`: a hold-out split's
held-in ones). With profiled offsets each channel's residual loses its mean over ALL its observed samples, held out
or not (`Objective.error`), while the sums run over the entries only: so the entries' co-moment, centred on their
own mean (`Gram`, Chan-Golub-LeVeque), is moved to the mean over the observed samples (summed beside it) by the
parallel-axis term n_e (m_e - m)(m_e - m)'.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from ..core.allocator import release_free_pages
from ..optimizers.normal import Gram
from ..sim.kernel import available_cores
from .corrections import SensorCorrection, corrected, is_sensor_unknown
from .experiment import Experiment
from .objectives import Objective


def forward_gram(
    experiment: Experiment,
    objective: Objective,
    values: Mapping[str, NDArray],
    scale: NDArray,
    entries: NDArray | None = None,
    corrections: tuple[SensorCorrection, ...] = (),
) -> NDArray:
    """(m + 1, m + 1): the Gram matrix of [J r] over the objective's residual entries (or `entries`, increasing
    indices into them), r the weighted residual of car 0 of `values` (the batch: name -> (m + 1,)) and column j of J
    the forward difference (r_{j + 1} - r_0) / scale[j] of the others'; the same sums as J'J, J'r and r'r of the
    whole vectors (to round-off), a block of BLOCK_SAMPLES at a time. The cars are split over the cores (each part
    running its own blocks) when called from the main thread. `corrections` (local ones: `Fault.local`) make each
    block's channels what the faulty chain recorded, their unknowns among `values`."""
    if not all(c.fault.local for c in corrections):
        raise ValueError("a correction that reads other samples (a delay, a drift) cannot be applied block by block")
    cars = len(next(iter(values.values())))
    width = cars  # m differences and the residual
    kept = objective.kept_masks(entries)
    observed = objective.observed
    grams = {f: Gram(ref.shape[-1], width, objective.offsets) for f, ref in objective.reference.items()}
    sums = {f: np.zeros((ref.shape[-1], width)) for f, ref in objective.reference.items()} if objective.offsets else {}
    parts = _parts(cars)
    car = {n: v for n, v in values.items() if not is_sensor_unknown(n)}
    gens = [experiment.simulate_blocks({n: v[s] for n, v in car.items()}) for s in parts]
    pool = ThreadPoolExecutor(len(gens)) if len(gens) > 1 else None
    try:
        while True:
            if pool is None:
                got = [_next_block(experiment, gens[0])]
            else:
                got = list(pool.map(lambda g: _next_block(experiment, g), gens))
            if got[0] is None:
                break
            k0 = got[0][0]
            block = {f: np.concatenate([g[1][f] for g in got]) if len(got) > 1 else got[0][1][f] for f in grams}
            if corrections:
                b = next(iter(block.values())).shape[1]
                corrected(tuple(c.samples(k0, k0 + b) for c in corrections), block, values)
            for family, gram in grams.items():
                V = _rows(objective, family, k0, block[family], scale)
                b = V.shape[0]
                gram.add(V, None if kept is None else kept[family][k0 : k0 + b])
                if family in sums:  # the sum over every observed sample: the profiled offset's mean
                    mask = None if observed is None else observed[family][k0 : k0 + b]
                    sums[family] += V.sum(axis=0) if mask is None else np.einsum("tk,tki->ki", mask, V)
            del got, block
    finally:
        if pool is not None:
            pool.shutdown()
    if experiment.long:
        release_free_pages()  # the blocks' freed memory back to the system (core/allocator.py)
    total = np.zeros((width, width))
    for family, gram in grams.items():
        S = gram.sums
        if family in sums:
            n = objective.reference[family].shape[0] if observed is None else np.sum(observed[family], axis=0)
            delta = gram.mean - sums[family] / np.asarray(n, dtype=float)[..., None]  # (k, width)
            S = S + gram.count[:, None, None] * delta[:, :, None] * delta[:, None, :]
        total += S.sum(axis=0)
    return total


def _next_block(experiment: Experiment, gen) -> tuple[int, dict[str, NDArray]] | None:
    """The next block of a part's cars as channels (first sample, family -> (cars, b, k)), or None at the end."""
    got = next(gen, None)
    if got is None:
        return None
    return got[0], experiment.read(got[1])


def _parts(cars: int) -> list[slice]:
    """The batch split into contiguous parts, one per core (from the main thread only, as `sim.kernel.in_parallel`:
    a caller already running threads keeps its own split)."""
    k = min(available_cores(), cars)
    if k <= 1 or threading.current_thread() is not threading.main_thread():
        return [slice(0, cars)]
    bounds = np.linspace(0, cars, k + 1).astype(int)
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _rows(objective: Objective, family: str, k0: int, sim: NDArray, scale: NDArray) -> NDArray:
    """(b, k, m + 1): each sample's rows [(r_j - r_0) / scale_j for j, r_0] of the block from k0 (sim (m + 1, b, k)),
    r = (reference - sim) / sigma before any offset is profiled."""
    b = sim.shape[1]
    sigma = np.asarray(objective.sigma[family], dtype=float)
    V = np.empty((b, sim.shape[2], sim.shape[0]))
    V[..., -1] = (objective.reference[family][k0 : k0 + b] - sim[0]) / sigma
    d = sim[1:] - sim[0]  # (m, b, k)
    d /= -sigma
    d /= np.asarray(scale, dtype=float)[:, None, None]
    V[..., :-1] = d.transpose(1, 2, 0)
    return V
