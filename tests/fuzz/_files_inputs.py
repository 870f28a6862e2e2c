"""Valid logger and bench files for the `files` fuzz families (tests/fuzz/files.py), and the damage done to them.

A tiny vehicle config (three sensors and the rig's four actuators, 1.2 s at 250 Hz, the deflection at 125 Hz in the
multi-rate formats) whose run vehid itself simulates and writes as MDF4, MAT v5, HDF5 and CSV (`io.write`), plus
the MATLAB v7.3 layout (an HDF5 file behind MATLAB's 512-byte header) that vehid reads but does not write; and a
tiny damper config with its bench CSV. `vehid check` on them takes about 0.1 s in process.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from . import baseline

RATE = 250.0  # Hz, the tiny run's grid
DURATION = 1.2  # s
SLOW = ("defl_fl",)  # sampled at half the rate in the multi-rate formats (MDF4, MAT, HDF5)
NAMES = {"acc_fl": "ACC_FL", "acc_rr": "ACC_RR", "defl_fl": "POT_FL"} | {f"road{i}": f"ACT{i}" for i in range(1, 5)}
UNITS = {"acc_fl": "g", "acc_rr": "g", "defl_fl": "mm"} | {f"road{i}": "mm" for i in range(1, 5)}

TINY_CONFIG = f"""system: vehicle
vehicle: {{m: 1300, mf: 40, mr: 65, Ix: 500, Iy: 2500, a1: 1.3, wheelbase: 2.6, b1: 0.75, track: 1.5,
  kf: 45000, kr: 80000, ktf: 200000, ktr: 200000, kR: 50000, cf: 2800, cr: 3500}}
road:
  input: actuators
  speed_kmh: 36
  random: {{iso_class: C, n_max: 3.0, fade_in: 0.3}}
simulation: {{duration: {DURATION}, dt: {1 / RATE}}}
layout:
  - {{name: acc_fl, kind: body_acc, origin: corner1}}
  - {{name: acc_rr, kind: body_acc, origin: corner3}}
  - {{name: defl_fl, kind: deflection, corner: 1}}
noise:
  sigma: {{acc: 0.05, disp: 0.0001}}
data:
  channels: {{{", ".join(f"{k}: {v}" for k, v in NAMES.items())}}}
  units: {{{", ".join(f"{k}: {v}" for k, v in UNITS.items())}}}
  offsets: identify
identify:
  unknowns: [m, kf]
  bounds: [0.8, 1.2]
  objective: wls
  algorithm: {{name: lsq, population: 4, iterations: 2}}
  runs: 1
  seed: 2026
"""

DAMPER_CONFIG = """system: damper
damper: {{model: viscous, parameters: {{c0: 1000.0}}}}
data:
  file: {data}
  columns: {{time: t_s, displacement: pos_mm, force: force_N}}
  units: {{displacement: mm{more_units}}}
identify: {{unknowns: [c0], budget: 8, runs: 1}}
"""


def _vehicle_channels() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The tiny car's run as SI channels: our name -> (t [s], values), simulated by vehid."""
    from vehid_cli.config import load_config
    from vehid_cli.core.streams import run_streams
    from vehid_cli.identify.experiment import build_experiment, simulate_measurement

    root = baseline().get("files-tiny.yaml", lambda p: p.write_text(TINY_CONFIG))
    cfg = load_config(root, [])
    experiment = build_experiment(cfg)
    run = simulate_measurement(experiment, run_streams(1, 0).noise)
    t = experiment.t
    out = {f"road{i + 1}": (t, experiment.road[:, i]) for i in range(4)}
    for family, values in run.channels.items():
        for k, name in enumerate(experiment.layout.names(family)):
            out[name] = (t, values[:, k] + (9.80665 if family == "acc" else 0.0))
    return out


def channels_si(multi_rate: bool = True) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """A copy of the run's channels (the slow ones at half the rate when `multi_rate`)."""
    import pickle

    path = baseline().get("files-run.pkl", lambda p: p.write_bytes(pickle.dumps(_vehicle_channels())))
    runs = pickle.loads(path.read_bytes())
    if multi_rate:
        runs = {k: (t[::2], y[::2]) if k in SLOW else (t, y) for k, (t, y) in runs.items()}
    return {k: (t.copy(), y.copy()) for k, (t, y) in runs.items()}


def write_run(path: Path, runs=None, names=None, units=None) -> Path:
    """The run (SI channels) written by vehid in the format of the path's suffix (.mat73: MATLAB v7.3 by h5py)."""
    from vehid_cli.io.write import write_record

    path = Path(path)
    names = dict(NAMES if names is None else names)
    units = dict(UNITS if units is None else units)
    if runs is None:
        runs = channels_si(multi_rate=path.suffix not in (".csv", ".txt"))
    if path.suffix == ".mat73":
        return write_mat73(path, runs, names, units)
    return write_record(path, runs, units=units, names=names, comment="fuzz baseline")


MAT73_HEADER = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Nov 14 20:07:10 2025 HDF5 schema 1.00 ."


def write_mat73(path: Path, runs, names, units, struct: str | None = "run", dataset_kw=None) -> Path:
    """MATLAB v7.3: an HDF5 file behind a 512-byte user block holding the MAT header; channels (in file units) as
    (1, n) datasets in a struct group `struct` (or at the top), `t` the fastest channels' stamps, `t_X` others'."""
    import h5py

    from vehid_cli.core.units import unit_factor

    t = max((tt for tt, _ in runs.values()), key=len)
    with h5py.File(path, "w", userblock_size=512) as f:
        g = f.create_group(struct) if struct else f
        if struct:
            g.attrs["MATLAB_class"] = np.bytes_("struct")
        items = [("t", t)]
        for ours, (tt, y) in runs.items():
            items.append((names[ours], y / unit_factor(units.get(ours, ""), "", "")))
            if len(tt) != len(t):
                items.append((f"t_{names[ours]}", tt))
        for name, values in items:
            d = g.create_dataset(name, data=np.asarray(values)[None, :], **(dataset_kw or {}))
            d.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        fh.write(MAT73_HEADER.ljust(116, b" ") + bytes(8) + b"\x00\x02" + b"IM")
    final = path.with_suffix(".mat")
    path.rename(final)
    return final


def valid_run(fmt: str) -> Path:
    """The baseline run in `fmt` (mf4, mat, mat73, h5, csv), built once."""
    suffix = {"mat73": ".mat"}.get(fmt, f".{fmt}")

    def build(tmp: Path) -> None:
        tmp.mkdir()
        made = write_run(tmp / f"run.{fmt}")
        made.rename(tmp / f"run{suffix}")

    return baseline().get(f"files-run-{fmt}", build) / f"run{suffix}"


def tiny_config(folder: Path) -> Path:
    """The tiny vehicle config, copied into the case's folder."""
    path = Path(folder) / "tiny.yaml"
    path.write_text(TINY_CONFIG)
    return path


def copy_of(src: Path, folder: Path, name: str | None = None) -> Path:
    dst = Path(folder) / (name or src.name)
    shutil.copyfile(src, dst)
    return dst


# ------------------------------------------------------------------------------------------ damage to bytes


def flip_bits(data: bytearray, rng: np.random.Generator, k: int, lo: int = 0, hi: int | None = None) -> str:
    hi = len(data) if hi is None else min(hi, len(data))
    at = rng.integers(lo, max(lo + 1, hi), size=k)
    for i in at:
        data[i] ^= 1 << int(rng.integers(8))
    return f"{k} bit(s) flipped in [{lo}, {hi})"


def set_bytes(data: bytearray, rng: np.random.Generator, k: int, lo: int = 0, hi: int | None = None) -> str:
    hi = len(data) if hi is None else min(hi, len(data))
    at = rng.integers(lo, max(lo + 1, hi), size=k)
    for i in at:
        data[i] = int(rng.choice([0, 0xFF, 0x7F, 0x80, int(rng.integers(256))]))
    return f"{k} byte(s) replaced in [{lo}, {hi})"


def zero_range(data: bytearray, rng: np.random.Generator) -> str:
    n = int(rng.integers(1, 512))
    at = int(rng.integers(0, max(1, len(data) - n)))
    data[at : at + n] = bytes(min(n, len(data) - at))
    return f"{n} bytes zeroed at {at}"


def truncate(data: bytearray, rng: np.random.Generator) -> str:
    at = int(rng.integers(0, len(data))) if rng.random() < 0.7 else int(rng.integers(0, min(len(data), 1024)))
    del data[at:]
    return f"truncated to {at} bytes"


def swap_blocks(data: bytearray, rng: np.random.Generator) -> str:
    n = int(rng.choice([8, 16, 64, 256]))
    a, b = (int(x) for x in rng.integers(0, max(1, len(data) - n), size=2))
    data[a : a + n], data[b : b + n] = data[b : b + n], data[a : a + n]
    return f"{n}-byte blocks at {a} and {b} swapped"


def inflate_count(data: bytearray, rng: np.random.Generator, counts, width: int = 8) -> str:
    """Replace a stored count (one of `counts`, little-endian, `width` bytes) by a huge one."""
    huge = int(rng.choice([2**34, 2**31 - 1, 2**40, 2**62, 2**63 - 1, 2**64 - 1]))
    huge = min(huge, 2 ** (8 * width) - 1)
    for count in counts:
        needle = int(count).to_bytes(width, "little")
        where = [i for i in range(len(data) - width) if data[i : i + width] == needle]
        if where:
            i = int(rng.choice(where))
            data[i : i + width] = huge.to_bytes(width, "little")
            return f"a stored {count} ({width} bytes) at {i} set to {huge}"
    return set_bytes(data, rng, 4)


def damage_bytes(data: bytearray, rng: np.random.Generator, header: int, markers=()) -> str:
    """One kind of damage to a file's bytes; `header`: the size of its header region (hit more often), `markers`
    the offsets of its block headers (MDF4 '##XX', HDF5 object headers)."""
    kind = rng.choice(["flip", "flip_head", "flip_block", "set", "zero", "truncate", "swap", "flip10"])
    if kind == "flip":
        return flip_bits(data, rng, int(rng.integers(1, 11)))
    if kind == "flip10":
        return set_bytes(data, rng, 10)
    if kind == "flip_head":
        return flip_bits(data, rng, int(rng.integers(1, 6)), 0, header)
    if kind == "flip_block" and len(markers):
        at = int(rng.choice(markers))
        return set_bytes(data, rng, int(rng.integers(1, 5)), at, at + 48) + " (a block header)"
    if kind == "set" or kind == "flip_block":
        return set_bytes(data, rng, int(rng.integers(1, 11)))
    if kind == "zero":
        return zero_range(data, rng)
    if kind == "truncate":
        return truncate(data, rng)
    return swap_blocks(data, rng)


def markers_of(data: bytes, tag: bytes) -> list[int]:
    out, at = [], data.find(tag)
    while at >= 0:
        out.append(at)
        at = data.find(tag, at + 1)
    return out


# ------------------------------------------------------------------------------------------ damage to values


def damage_values(runs, rng: np.random.Generator) -> str:
    """Hostile numbers in a run's channels (in place): NaN/Inf/huge samples or stamps, stamps non-monotonic,
    constant, in ms, shifted (one channel's clock inconsistent), duplicated, or a channel shortened."""
    name = str(rng.choice(list(runs)))
    t, y = runs[name]
    kind = rng.choice(
        ["nan", "inf", "huge", "tiny", "backwards", "constant_t", "ms", "shift", "dup", "short", "zero_y", "gap", "one"]
    )
    k = int(rng.integers(0, y.size))
    if kind in ("nan", "inf", "huge", "tiny"):
        value = {"nan": np.nan, "inf": np.inf * rng.choice([-1, 1]), "huge": 1e300, "tiny": 5e-324}[kind]
        (y if rng.random() < 0.6 else t)[k] = value
    elif kind == "backwards":
        m = int(rng.integers(2, 20))
        t[k : k + m] = t[k : k + m][::-1].copy()
    elif kind == "constant_t":
        t[:] = t[0]
    elif kind == "ms":
        t *= 1000.0
    elif kind == "shift":
        t += float(rng.choice([0.5, -3.0, 100.0, 1e6, 1e-7]))
    elif kind == "dup":
        t[k:] = np.concatenate([[t[k]], t[k:-1]]) if k > 0 else t[k:]
    elif kind == "short":
        n = int(rng.integers(0, 6))
        runs[name] = (t[:n], y[:n])
    elif kind == "zero_y":
        y[:] = 0.0
    elif kind == "gap":
        t[k:] += 0.5
    else:  # one channel's stamps at another rate: inconsistent time scales between channels
        runs[name] = (t * float(rng.choice([1e-3, 1e3, 7.0])), y)
    return f"{kind} in channel '{name}' (sample {k})"


def write_raw(path: Path, runs, names=None, units=None) -> Path:
    """The channels (SI) written by the format's own writer, unchecked (hostile values reach the file as they are;
    a CSV is written by hand: one time column, the first channel's, and the channels' values as they are)."""
    from vehid_cli.core.units import unit_factor
    from vehid_cli.io.formats import FORMATS

    path = Path(path)
    names = dict(NAMES if names is None else names)
    units = dict(UNITS if units is None else units)
    inner = {o: (t, y / unit_factor(units.get(o, ""), "", "")) for o, (t, y) in runs.items()}
    if path.suffix == ".mat73":
        return write_mat73(path, runs, names, units)
    if path.suffix == ".csv":
        n = max(y.size for _, y in inner.values())
        t = next(t for t, y in inner.values() if y.size == n)
        cols = [t] + [np.resize(y, n) if y.size else np.full(n, np.nan) for _, y in inner.values()]
        head = "t," + ",".join(f"{names[o]} [{units.get(o) or 'SI'}]" for o in inner)
        rows = "".join(",".join(map(repr, r)) + "\n" for r in np.column_stack(cols).tolist())
        path.write_text(head + "\n" + rows.replace("nan", ""))
        return path
    with np.errstate(all="ignore"):  # the writer's own rate of a hostile time vector
        FORMATS[path.suffix].write(path, inner, names, {o: units.get(o, "") for o in inner}, start=None, comment="")
    return path
