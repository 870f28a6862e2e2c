"""Fuzz families of logger and bench files (issue 22, the `files` share): `csv`, `mdf4`, `matv5`, `matv73`,
`hdf5data`, `bench_csv`, `rates`.

Each case takes a valid run vehid wrote itself (`_files_inputs`: a tiny car, 1.2 s at 250 Hz) and damages it the
way a disk, a transfer or another tool does: its bytes (truncation, 1 to 10 flipped bits or bytes anywhere or in a
header or block, zeroed ranges, swapped blocks, a stored count inflated to 2**34 and beyond), its structure
(wrong dtypes, odd shapes, duplicate or empty names, non-UTF-8 units, links, filters), its numbers (NaN, Inf,
huge, time stamps backwards, constant, in ms, shifted, inconsistent between channels) or the options that drive
reading (`data.rate`, `data.time_unit`, `data.window`). The command is `vehid check` (about 0.1 s) and sometimes
`vehid identify` with a budget of a few evaluations.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Case, family
from ._files_inputs import (
    NAMES,
    UNITS,
    channels_si,
    copy_of,
    damage_bytes,
    damage_values,
    inflate_count,
    markers_of,
    tiny_config,
    valid_run,
    write_raw,
)

N_FAST = 300  # samples of the tiny run's fast channels


def _command(rng: np.random.Generator, config: Path, data: Path, *sets: str, identify: float = 0.1) -> tuple:
    """`vehid check CONFIG --data FILE`, or (a share `identify` of cases) `vehid identify` with a tiny budget."""
    opts = [a for s in sets for a in ("--set", s)]
    if rng.random() < identify:
        return ("identify", str(config), "--data", str(data), "-o", "out.h5", "--runs", "1", "--jobs", "1", *opts)
    return ("check", str(config), "--data", str(data), *opts)


def _bytes_case(name: str, rng, folder: Path, fmt: str, header: int, tag: bytes, counts) -> Case:
    src = valid_run(fmt)
    data = bytearray(src.read_bytes())
    if rng.random() < 0.2:
        what = inflate_count(data, rng, counts, width=int(rng.choice([8, 4])))
    else:
        what = damage_bytes(data, rng, header, markers_of(bytes(data), tag))
    path = folder / src.name
    path.write_bytes(bytes(data))
    config = tiny_config(folder)
    return Case(name, f"{fmt}: {what}", _command(rng, config, path))


def _values_case(name: str, rng, folder: Path, suffix: str) -> Case:
    runs = channels_si(multi_rate=suffix != ".csv")
    what = damage_values(runs, rng)
    path = write_raw(folder / f"run{suffix}", runs)
    config = tiny_config(folder)
    sets = []
    if rng.random() < 0.2:
        sets.append(f"data.time_unit={rng.choice(['ms', 'us', 'min', 'h'])}")
    return Case(name, f"{suffix}: {what} {sets}", _command(rng, config, path, *sets))


# ------------------------------------------------------------------------------------------ CSV


def _csv_text_damage(text: str, rng) -> tuple[str, str]:
    lines = [ln for ln in text.splitlines() if not ln.startswith("#")]
    kind = rng.choice(["dup_header", "empty_header", "cells", "non_utf8", "short_row", "iso", "one_row", "long"])
    if kind == "dup_header":
        head = lines[0].split(",")
        head[int(rng.integers(0, len(head)))] = head[int(rng.integers(0, len(head)))]
        lines[0] = ",".join(head)
    elif kind == "empty_header":
        head = lines[0].split(",")
        head[int(rng.integers(0, len(head)))] = str(rng.choice(["", " ", "[g]", "(mm)", "t"]))
        lines[0] = ",".join(head)
    elif kind == "cells":
        for _ in range(int(rng.integers(1, 10))):
            r = int(rng.integers(1, len(lines)))
            cells = lines[r].split(",")
            cells[int(rng.integers(0, len(cells)))] = str(
                rng.choice(["nan", "inf", "-inf", "1e999", "", "x", "1,5", "0x1F", "1e-400", "9" * 400, "--1"])
            )
            lines[r] = ",".join(cells)
    elif kind == "non_utf8":
        return text[: len(text) // 2] + "\udcff", "non-UTF-8 bytes"
    elif kind == "short_row":
        r = int(rng.integers(1, len(lines)))
        lines[r] = lines[r].rsplit(",", 1)[0]
    elif kind == "iso":
        for r in range(1, len(lines)):
            cells = lines[r].split(",")
            cells[0] = f"2025-11-14 20:07:{10 + float(cells[0]):09.6f}" if rng.random() < 0.98 else "2025-13-40"
            lines[r] = ",".join(cells)
    elif kind == "one_row":
        lines = lines[: int(rng.integers(1, 4))]
    else:
        lines[0] = lines[0] + "," + "X" * int(rng.integers(300, 100_000))
        lines[1:] = [ln + ",1" for ln in lines[1:]]
    return "\n".join(lines) + "\n", kind


@family("csv")
def csv_case(rng: np.random.Generator, folder: Path) -> Case:
    """The tiny run as a logger's CSV export: its bytes, its text or its numbers damaged."""
    r = rng.random()
    if r < 0.35:
        return _values_case("csv", rng, folder, ".csv")
    if r < 0.6:
        return _bytes_case("csv", rng, folder, "csv", 200, b"\n", [N_FAST])
    text = valid_run("csv").read_text()
    text, what = _csv_text_damage(text, rng)
    path = folder / "run.csv"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    return Case("csv", f"csv: {what}", _command(rng, tiny_config(folder), path))


# ------------------------------------------------------------------------------------------ MDF4


def _mdf4_structure(rng, folder: Path) -> tuple[Path, str]:
    """An MDF4 file written by asammdf with a hostile structure: dtypes, shapes, names, units, stamps."""
    from asammdf import MDF, Signal

    runs = channels_si()
    kind = str(rng.choice(["int", "bytes", "2d", "dup", "empty_name", "unit", "nan_t", "no_samples", "bool"]))
    mdf = MDF(version="4.10")
    signals = []
    for ours, (t, y) in runs.items():
        name, unit = NAMES[ours], UNITS[ours]
        samples = y
        if kind == "int" and rng.random() < 0.5:
            samples = (y * 1000).astype(rng.choice([np.int8, np.uint16, np.int64]))
        elif kind == "bytes" and rng.random() < 0.3:
            samples = np.array([b"abc"] * y.size)
        elif kind == "2d" and rng.random() < 0.3:
            samples = np.repeat(y[:, None], 3, axis=1)
        elif kind == "bool" and rng.random() < 0.3:
            samples = y > y.mean()
        elif kind == "empty_name" and rng.random() < 0.3:
            name = str(rng.choice([" ", "\x00", "ACC_FL", "a" * 300]))  # asammdf refuses an empty one
        elif kind == "unit" and rng.random() < 0.5:
            unit = str(rng.choice(["\u00b5m", "g\x00", "m/s^2", "x" * 5000, "[mm]", "kg"]))
        elif kind == "nan_t" and rng.random() < 0.3:
            t = t.copy()
            t[int(rng.integers(t.size))] = np.nan
        elif kind == "no_samples" and rng.random() < 0.3:
            t, samples = t[:0], samples[:0]
        try:
            signals.append(Signal(samples, t, name=name, unit=unit))
        except Exception:  # noqa: BLE001 - asammdf refuses some names and shapes itself: keep the channel as it was
            signals.append(Signal(y, runs[ours][0], name=NAMES[ours], unit=UNITS[ours]))
    if kind == "dup":
        signals.append(signals[int(rng.integers(len(signals)))])
    for s in signals:
        mdf.append([s])
    path = folder / "run.mf4"
    with open(path, "wb+") as fh:
        mdf.save(fh, overwrite=True, compression=int(rng.integers(0, 3)))
    mdf.close()
    return path, kind


@family("mdf4")
def mdf4_case(rng: np.random.Generator, folder: Path) -> Case:
    """The tiny run as vehid writes MDF4: bytes damaged (the block table, a channel group's cycle count), or a
    hostile structure or numbers."""
    r = rng.random()
    if r < 0.6:
        return _bytes_case("mdf4", rng, folder, "mf4", 64 + 104, b"##", [N_FAST, N_FAST // 2])
    if r < 0.8:
        return _values_case("mdf4", rng, folder, ".mf4")
    if rng.random() < 0.3:  # compressed data blocks (DZ) damaged
        path, kind = _mdf4_structure(rng, folder)
        data = bytearray(path.read_bytes())
        what = damage_bytes(data, rng, 168, markers_of(bytes(data), b"##DZ"))
        path.write_bytes(bytes(data))
        kind = f"{kind} and {what}"
    else:
        path, kind = _mdf4_structure(rng, folder)
    return Case("mdf4", f"mdf4 structure: {kind}", _command(rng, tiny_config(folder), path))


# ------------------------------------------------------------------------------------------ MAT v5


def _matv5_structure(rng, folder: Path) -> tuple[Path, str]:
    import scipy.io

    runs = channels_si()
    t = runs["acc_fl"][0]
    variables = {"t": t}
    kind = str(rng.choice(["string", "cell", "2d", "complex", "empty", "int", "struct", "units", "nested", "bool"]))
    for ours, (tt, y) in runs.items():
        name = NAMES[ours]
        value = y
        if rng.random() < 0.35:
            value = {
                "string": "not a number",
                "cell": np.array([[1.0], "a"], dtype=object),
                "2d": np.repeat(y[:, None], 2, axis=1),
                "complex": y + 1j,
                "empty": np.zeros((0, 0)),
                "int": (y * 100).astype(np.int16),
                "struct": {"a": y},
                "units": y,
                "nested": {"x": {"y": y}},
                "bool": y > 0,
            }[kind]
        variables[name] = value
        if tt.size != t.size:
            variables[f"t_{name}"] = tt
    if kind == "units":
        odd = [1.5, "g\udcff".encode("utf-8", "surrogateescape"), "", "x" * 3000]
        variables["units"] = {NAMES[o]: odd[int(rng.integers(len(odd)))] for o in runs}
    else:
        variables["units"] = {NAMES[o]: UNITS[o] for o in runs}
    path = folder / "run.mat"
    scipy.io.savemat(path, variables, oned_as="column", do_compression=bool(rng.random() < 0.5))
    return path, kind


@family("matv5")
def matv5_case(rng: np.random.Generator, folder: Path) -> Case:
    """MAT v5 as vehid writes it (uncompressed or compressed): its header, tags and sizes damaged, or hostile
    variables (strings, cells, matrices, complex, structs) in place of channels."""
    r = rng.random()
    if r < 0.45:
        return _bytes_case("matv5", rng, folder, "mat", 128 + 64, b"\x0e\x00\x00\x00", [N_FAST, N_FAST * 8])
    if r < 0.65:
        import scipy.io

        path = folder / "run.mat"
        variables = {k: v for k, v in scipy.io.loadmat(valid_run("mat")).items() if not k.startswith("__")}
        scipy.io.savemat(path, variables, do_compression=True)
        data = bytearray(path.read_bytes())
        what = damage_bytes(data, rng, 128 + 64, markers_of(bytes(data), b"\x0f\x00\x00\x00"))
        path.write_bytes(bytes(data))
        return Case("matv5", f"compressed mat: {what}", _command(rng, tiny_config(folder), path))
    if r < 0.8:
        return _values_case("matv5", rng, folder, ".mat")
    path, kind = _matv5_structure(rng, folder)
    return Case("matv5", f"mat v5 structure: {kind}", _command(rng, tiny_config(folder), path))


# ------------------------------------------------------------------------------------------ HDF5 and MAT v7.3


def _h5_structure(rng, path: Path, matlab: bool) -> str:
    """Rewrite a valid HDF5 / v7.3 file with one hostile structure."""
    import h5py

    kind = str(rng.choice(["unit_bytes", "unit_array", "unit_int", "2d", "scalar", "empty", "compound", "string",
                           "group", "softloop", "external", "fletcher", "gzip", "time_2d", "unit_long"]))  # fmt: skip
    with h5py.File(path, "r+") as f:
        root = f["run"] if matlab else f
        datasets = []
        root.visititems(lambda n, o: datasets.append(n) if isinstance(o, h5py.Dataset) else None)
        name = str(rng.choice([d for d in datasets if "t" not in d.split("/")[-1][:2]] or datasets))
        if kind == "time_2d":
            name = "t" if "t" in root else "time"
        d = root[name]
        values = np.ravel(d[()])
        if kind == "unit_bytes":
            d.attrs["unit"] = np.bytes_(b"\xff\xfe m/s\xc3")
        elif kind == "unit_array":
            d.attrs["unit"] = np.array([1.0, 2.0])
        elif kind == "unit_int":
            d.attrs["unit"] = 7
        elif kind == "unit_long":
            d.attrs["unit"] = "mm" * 50_000
        else:
            del root[name]
            new = {
                "2d": lambda: root.create_dataset(name, data=np.repeat(values[:, None], 3, axis=1)),
                "time_2d": lambda: root.create_dataset(name, data=np.repeat(values[:, None], 2, axis=1)),
                "scalar": lambda: root.create_dataset(name, data=1.5),
                "empty": lambda: root.create_dataset(name, shape=(0,), dtype=float),
                "compound": lambda: root.create_dataset(
                    name, data=np.array([(v, 1) for v in values], dtype=[("a", float), ("b", int)])
                ),
                "string": lambda: root.create_dataset(name, data=np.array([b"x"] * values.size)),
                "group": lambda: root.create_group(name),
                "softloop": lambda: (
                    root.__setitem__(name, h5py.SoftLink(f"/{name}_loop"))
                    or root.__setitem__(f"{name}_loop", h5py.SoftLink(f"/{name}"))
                ),
                "external": lambda: root.__setitem__(name, h5py.ExternalLink("missing.h5", "/x")),
                "fletcher": lambda: root.create_dataset(name, data=values, chunks=(16,), fletcher32=True),
                "gzip": lambda: root.create_dataset(name, data=values, chunks=(16,), compression="gzip"),
            }[kind]()
            if isinstance(new, h5py.Dataset) and matlab:
                new.attrs["MATLAB_class"] = np.bytes_("double")
    if kind in ("fletcher", "gzip") and rng.random() < 0.8:  # then damage the chunks' bytes
        data = bytearray(path.read_bytes())
        kind += " " + damage_bytes(data, rng, 0, [])
        path.write_bytes(bytes(data))
    return kind


def _h5_case(name: str, rng, folder: Path, fmt: str) -> Case:
    r = rng.random()
    if r < 0.45:
        header = 512 + 96 if fmt == "mat73" else 96
        return _bytes_case(name, rng, folder, fmt, header, b"OHDR", [N_FAST, N_FAST // 2])
    if r < 0.6:
        return _values_case(name, rng, folder, ".mat73" if fmt == "mat73" else ".h5")
    if fmt == "mat73" and r < 0.7:  # the MATLAB header itself
        path = copy_of(valid_run(fmt), folder)
        data = bytearray(path.read_bytes())
        what = damage_bytes(data, rng, 128, [0, 116, 124])
        path.write_bytes(bytes(data[: max(len(data), 1)]))
        return Case(name, f"mat73 header: {what}", _command(rng, tiny_config(folder), path))
    path = copy_of(valid_run(fmt), folder)
    kind = _h5_structure(rng, path, matlab=fmt == "mat73")
    return Case(name, f"{fmt} structure: {kind}", _command(rng, tiny_config(folder), path))


@family("matv73")
def matv73_case(rng: np.random.Generator, folder: Path) -> Case:
    """MATLAB v7.3 (HDF5 behind a 512-byte header): its header, superblock, object headers and chunks damaged,
    non-UTF-8 or odd unit attributes, odd shapes and dtypes, links that loop or lead nowhere."""
    return _h5_case("matv73", rng, folder, "mat73")


@family("hdf5data")
def hdf5data_case(rng: np.random.Generator, folder: Path) -> Case:
    """HDF5 as vehid writes it, damaged as `matv73` is."""
    return _h5_case("hdf5data", rng, folder, "h5")


# ------------------------------------------------------------------------------------------ damper bench CSV


def _bench_rows(rng) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    n = int(rng.choice([200, 200, 200, 50, 12, 5, 2000]))
    t = np.arange(n) * 0.01
    x = 10 * np.sin(2 * np.pi * t)
    force = 50 * np.cos(2 * np.pi * t)
    kind = str(rng.choice(["ms_as_s", "s_as_ms", "backwards", "constant_t", "nan", "inf", "huge", "constant_f",
                           "jitter", "gap", "ok", "us_as_s", "tiny_steps", "negative_t"]))  # fmt: skip
    k = int(rng.integers(1, n - 1))
    if kind == "ms_as_s":
        t = t * 1000.0
    elif kind == "us_as_s":
        t = t * 1e6
    elif kind == "s_as_ms":
        t = t / 1000.0
    elif kind == "tiny_steps":
        t = t * 1e-9
    elif kind == "negative_t":
        t = t - 1e9
    elif kind == "backwards":
        t[k], t[k - 1] = t[k - 1], t[k]
    elif kind == "constant_t":
        t[:] = 1.0
    elif kind in ("nan", "inf", "huge"):
        (x if rng.random() < 0.5 else force)[k] = {"nan": np.nan, "inf": np.inf, "huge": 1e300}[kind]
    elif kind == "constant_f":
        force[:] = 3.0
    elif kind == "jitter":
        t = t + rng.uniform(-0.4, 0.4, n) * 0.01
    elif kind == "gap":
        t[k:] += 5.0
    return t, x, force, f"{kind}, {n} rows"


@family("bench_csv")
def bench_csv_case(rng: np.random.Generator, folder: Path) -> Case:
    """A damper bench CSV (t_s, pos_mm, force_N) with hostile time columns and values, identified with a budget
    of 8 evaluations; sometimes read in ms/us or at a declared sample rate."""
    t, x, force, what = _bench_rows(rng)
    path = folder / "bench.csv"
    rows = "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(t.tolist(), x.tolist(), force.tolist(), strict=True))
    text = "t_s,pos_mm,force_N\n" + rows
    if rng.random() < 0.25:
        data = bytearray(text.encode())
        what += "; " + damage_bytes(data, rng, 40, [])
        text = data.decode("utf-8", "surrogateescape")
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    more = ""
    if rng.random() < 0.25:
        more = f", time: {rng.choice(['ms', 'us', 'min', 'h'])}"
    config = folder / "damper.yaml"
    config.write_text(
        f"system: damper\ndamper: {{model: viscous, parameters: {{c0: 1000.0}}}}\ndata:\n  file: bench.csv\n"
        f"  columns: {{time: t_s, displacement: pos_mm, force: force_N}}\n  units: {{displacement: mm{more}}}\n"
        f"identify: {{unknowns: [c0], budget: 8, runs: 1}}\n"
    )
    sets = []
    if rng.random() < 0.25:
        sets.append(f"data.sample_rate={rng.choice(['100', '1e9', '1e-3', '99.5', '1000'])}")
    if rng.random() < 0.15:
        sets.append(f"data.window=[{rng.choice(['0', '0.5', '1e6'])}, {rng.choice(['1', '2', '1e9'])}]")
    opts = [a for s in sets for a in ("--set", s)]
    args = ("identify", str(config), "-o", "out.h5", "--jobs", "1", *opts)
    return Case("bench_csv", f"bench csv: {what}{more} {sets}", args)


# ------------------------------------------------------------------------------------------ rates


@family("rates")
def rates_case(rng: np.random.Generator, folder: Path) -> Case:
    """`data.rate` (the grid rate) against the record: huge (1e9, 1e12: the grid's memory), tiny, odd, with
    short files (3 to 40 samples: the anti-alias filter's padding) and windows, in every format."""
    fmt = str(rng.choice(["csv", "mf4", "mat", "h5", "mat73"]))
    rate = rng.choice(["1e9", "1e12", "1e6", "2e5", "0.5", "3", "1e-3", "100", "62.5", "124", "250", "1e300",
                       "5e-324", "nan", "-1", "0", "inf", f"{10 ** rng.uniform(-3, 13):.6g}"])  # fmt: skip
    runs = channels_si(multi_rate=fmt != "csv")
    what = f"data.rate={rate} on {fmt}"
    if rng.random() < 0.5:  # a short file
        n = int(rng.integers(3, 41))
        runs = {k: (t[:n], y[:n]) if k != "defl_fl" or fmt == "csv" else (t[: max(3, n // 2)], y[: max(3, n // 2)])
                for k, (t, y) in runs.items()}  # fmt: skip
        what += f", {n} samples"
    suffix = {"mat73": ".mat73"}.get(fmt, f".{fmt}")
    path = write_raw(folder / f"run{suffix}", runs)
    sets = [f"data.rate={rate}"]
    if rng.random() < 0.2:
        sets.append(f"data.window=[{rng.choice(['0', '0.01', '1'])}, {rng.choice(['0.02', '0.5', '1e9'])}]")
    if rng.random() < 0.15:
        sets.append("data.resample=false")
    return Case("rates", what + f" {sets[1:]}", _command(rng, tiny_config(folder), path, *sets))
