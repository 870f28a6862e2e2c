"""The same known run written as a vehicle logger would (MDF4), as test engineers pass it on (MAT v5, MAT v7.3,
HDF5) and as a logger's CSV export (ISO time stamps, jittered 300 Hz): `truth` is what reading must give back."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import h5py
import numpy as np
import scipy.io
from numpy.typing import NDArray

G = 9.80665  # m/s² per g
DURATION = 4.0  # s
# file name -> (our name, unit in the file, rate [Hz] in the MDF4 file, offset, amplitude, frequency [Hz], phase)
SIGNALS = {
    "ACC_FL_Z": ("acc_fl", "g", 1000, 0.05, 0.3, 3.0, 0.0),
    "ACC_HF_Z": ("acc_hf", "g", 1000, 0.0, 0.1, 4.0, 0.0),  # + 0.5 g at 150 Hz (above 100 Hz, see HF_*)
    "ACC_RR_Z": ("acc_rr", "g", 200, -0.02, 0.2, 11.0, 0.3),
    "DISP_FL": ("disp_fl", "mm", 200, 4.0, 12.0, 2.0, 0.0),
}
HF_AMPLITUDE, HF_FREQUENCY = 0.5, 150.0  # g, Hz: the part of acc_hf a 200 Hz grid must filter out
FACTOR = {"g": G, "mm": 1e-3}
CHANNELS = {ours: theirs for theirs, (ours, *_) in SIGNALS.items()}
START = dt.datetime(2025, 11, 14, 20, 7, 10, 531160)


def in_file_units(name: str, t: NDArray) -> NDArray:
    """Channel `name` (file name) at times t, in the unit the file declares."""
    _, _, _, offset, amplitude, frequency, phase = SIGNALS[name]
    y = offset + amplitude * np.sin(2 * np.pi * frequency * t + phase)
    if name == "ACC_HF_Z":
        y = y + HF_AMPLITUDE * np.sin(2 * np.pi * HF_FREQUENCY * t)
    return y


def truth(ours: str, t: NDArray, low_pass: bool = False) -> NDArray:
    """Our channel at times t in SI units; `low_pass`: without the 150 Hz part of acc_hf."""
    name = CHANNELS[ours]
    y = in_file_units(name, t)
    if low_pass and name == "ACC_HF_Z":
        y = y - HF_AMPLITUDE * np.sin(2 * np.pi * HF_FREQUENCY * t)
    return y * FACTOR[SIGNALS[name][1]]


def offset_si(ours: str) -> float:
    name = CHANNELS[ours]
    return SIGNALS[name][3] * FACTOR[SIGNALS[name][1]]


def _grid(rate: float) -> NDArray:
    return np.arange(int(DURATION * rate)) / rate


def write_mdf4(path: Path) -> None:
    """Two channel groups, 1 kHz and 200 Hz, each channel with its unit string."""
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    for rate in (1000, 200):
        t = _grid(rate)
        mdf.append(
            [Signal(in_file_units(n, t), t, name=n, unit=s[1]) for n, s in SIGNALS.items() if s[2] == rate],
            comment=f"{rate} Hz",
        )
    mdf.save(path, overwrite=True)
    mdf.close()


def _common(rate: float = 1000) -> dict[str, NDArray]:
    t = _grid(rate)
    return {"t": t} | {n: in_file_units(n, t) for n in SIGNALS}


def write_mat5(path: Path) -> None:
    """A struct `run` with a time vector `t` and the channels (file units) at 1 kHz, beside an unrelated variable."""
    scipy.io.savemat(path, {"run": _common(), "operator": "TK"})


MAT73_HEADER = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Nov 14 20:07:10 2025 HDF5 schema 1.00 ."


def write_mat73(path: Path) -> None:
    """MATLAB's v7.3 layout: an HDF5 file behind a 512-byte user block whose first 128 bytes are the MAT header
    (116 bytes of text, 8 of subsystem offset, version 0x0200, 'IM'); a struct is a group with MATLAB_class
    'struct', a double column vector (n x 1) a dataset of shape (1, n) (MATLAB writes column-major)."""
    with h5py.File(path, "w", userblock_size=512) as f:
        g = f.create_group("run")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, values in _common().items():
            d = g.create_dataset(name, data=values[None, :])
            d.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        fh.write(MAT73_HEADER.ljust(116, b" ") + bytes(8) + b"\x00\x02" + b"IM")


def write_hdf5(path: Path) -> None:
    """Datasets by path, /time and /acc/..., /disp/..., each with a `unit` attribute."""
    with h5py.File(path, "w") as f:
        for name, values in _common().items():
            d = f.create_dataset("time" if name == "t" else f"{name.split('_')[0].lower()}/{name}", data=values)
            d.attrs["unit"] = "s" if name == "t" else SIGNALS[name][1]


def csv_times(rate: float = 300.0, jitter: float = 0.02, seed: int = 7) -> NDArray:
    """Stamps at `rate` moved by up to ±jitter of a step (the first one not), to the microsecond."""
    rng = np.random.default_rng(seed)
    k = np.arange(int(DURATION * rate))
    t = (k + rng.uniform(-jitter, jitter, k.size) * (k > 0)) / rate
    return np.round(t * 1e6) / 1e6


def write_csv(path: Path, t: NDArray | None = None) -> None:
    """A logger's CSV export: ISO date-time stamps (jittered 300 Hz), channels in file units, no unit row."""
    t = csv_times() if t is None else t
    stamps = [(START + dt.timedelta(microseconds=int(round(x * 1e6)))).isoformat(sep=" ") for x in t]
    names = list(SIGNALS)
    rows = [",".join([s] + [repr(float(in_file_units(n, x))) for n in names]) for s, x in zip(stamps, t, strict=True)]
    path.write_text("timestamp," + ",".join(names) + "\n" + "\n".join(rows) + "\n")


WRITERS = {"mf4": write_mdf4, "mat": write_mat5, "mat73": write_mat73, "h5": write_hdf5, "csv": write_csv}


def write_logger_run(path: Path, fmt: str) -> Path:
    """Write the known run in `fmt` (mf4, mat, mat73, h5, csv) to `path` (its suffix chosen by the caller)."""
    WRITERS[fmt](Path(path))
    return Path(path)
