"""What a damper campaign concludes after its runs (`Findings`): the identified model, J on the held-out runs, the
real-time check and the measured/model force traces; written into and read from the campaign file's /damper group."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
from numpy.typing import NDArray

from ...core.result import Result
from .fit import RealTime


@dataclass(frozen=True)
class Trace(Result):
    """Measured and model force on one bench run (for the figures), with J on it."""

    name: str
    t: NDArray
    x: NDArray
    v: NDArray
    measured: NDArray
    model: NDArray
    J: float


@dataclass(frozen=True)
class Findings(Result):
    """What a damper campaign adds after its runs: the identified model (run 0's, every parameter), J on the
    held-out runs, the real-time check, and measured/model force traces (training and held out)."""

    model: str
    names: tuple[str, ...]  # the whole parameter row of the identified model
    values: NDArray
    validation: tuple[tuple[str, float], ...]  # (file, J) on held-out runs
    realtime: RealTime
    traces: tuple[Trace, ...]

    def write_h5(self, group) -> None:
        """Into the results file's /damper group (the layout campaign/results.py documents: the validation pairs
        as two datasets, the model row under model_names / model_values); the real-time check and the traces as
        the Result protocol writes them."""
        strings = h5py.string_dtype()
        group.attrs["model"] = self.model
        group.create_dataset("model_names", data=np.array(self.names, dtype=strings))
        group.create_dataset("model_values", data=self.values)
        v = group.create_group("validation")
        v.create_dataset("files", data=np.array([f for f, _ in self.validation], dtype=strings))
        v.create_dataset("J", data=np.array([j for _, j in self.validation], dtype=float))
        self.realtime.write_h5(group.create_group("realtime"))
        tg = group.create_group("traces")
        for k, tr in enumerate(self.traces):
            tr.write_h5(tg.create_group(f"{k:02d}"))

    def json_keys(self, campaign) -> dict:
        """The damper's keys of the JSON summary: J per run and of the truth, held-out J, the model (every parameter
        of its row, with their SI units), real time."""
        rt, recs = self.realtime, campaign.records
        return {
            "model": self.model,
            "J": [float(r.cost) for r in recs],
            "J_truth": None if campaign.truth is None else [float(r.truth_cost) for r in recs],
            "J_train": float(np.mean([r.cost for r in recs])),
            "validation_J": {Path(f).name: j for f, j in self.validation},
            "model_row": {n: float(v) for n, v in zip(self.names, self.values, strict=True)},
            "model_row_units": campaign.config.units(self.names),
            "realtime": rt.to_json(),
        }

    @classmethod
    def read_h5(cls, group) -> Findings:
        """From a results file's /damper group (KeyError for a damaged one)."""
        model = str(group.attrs["model"])
        realtime = RealTime.read_h5(group["realtime"], model=model)
        traces = tuple(Trace.read_h5(t) for _, t in sorted(group["traces"].items()))
        files = _text(group["validation/files"][()])
        names, values = _text(group["model_names"][()]), np.asarray(group["model_values"][()])
        if values.shape != (len(names),) or values.dtype.kind not in "fiu":
            raise ValueError(f"model_values of shape {values.shape} and type {values.dtype} for {len(names)} names")
        return cls(
            model=model, names=names, values=values.astype(float),
            validation=tuple(zip(files, map(float, group["validation/J"][()]), strict=True)), realtime=realtime,
            traces=traces,
        )  # fmt: skip


def _text(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)
