"""write_record round trips: a two-rate run (1 kHz and 200 Hz) written with odd file names in g and mm reads back
(read_record) as the SI values written; bad input is an InputError naming the file and the channel."""

from __future__ import annotations

import datetime as dt

import h5py
import numpy as np
import pytest
import scipy.io

from vehid_cli.core.errors import InputError
from vehid_cli.io.read import read_record
from vehid_cli.io.write import write_record

G = 9.80665  # m/s² per g, as written here (not taken from the package)
T1K = np.arange(3000) / 1000  # [s]
T200 = np.arange(600) / 200
ACC = 0.05 * G + 0.3 * G * np.sin(2 * np.pi * 3 * T1K)  # [m/s²] at 1 kHz
DISP = 0.004 + 0.012 * np.sin(2 * np.pi * 2 * T200 + 0.3)  # [m] at 200 Hz
CHANNELS = {"acc": (T1K, ACC), "disp": (T200, DISP)}
UNITS = {"acc": "g", "disp": "mm"}
START = dt.datetime(2025, 11, 14, 20, 7, 10, 531160)
# odd names in the file: spaces, brackets, a path (HDF5); MATLAB names for MAT files
NAMES = {
    "mf4": {"acc": "ACC FL-Z [raw]", "disp": "Disp.FL (pot)"},
    "mat": {"acc": "ACC_FL_Z", "disp": "DISP_FL_pot"},
    "h5": {"acc": "chassis/ACC FL-Z [raw]", "disp": "susp/Disp.FL (pot)"},
}


@pytest.mark.parametrize("fmt", ["mf4", "mat", "h5"])
def test_two_rates_in_g_and_mm_read_back_as_the_si_values_written(tmp_path, fmt):
    path = write_record(tmp_path / f"run.{fmt}", CHANNELS, units=UNITS, names=NAMES[fmt], start=START, comment="x")
    rec = read_record(path, NAMES[fmt])  # the units the file declares
    assert rec.rates == {"acc": 1000.0, "disp": 200.0}
    n = 2996  # the common span: to 2.995 s, the last 200 Hz sample
    assert rec.t.size == n and rec.rate == pytest.approx(1000.0, rel=1e-12)
    # the 1 kHz channel: its samples as written, to the round-off of / g * g
    assert np.array_equal(rec.native_samples("acc"), np.arange(n))
    assert np.max(np.abs(rec.channels["acc"] - ACC[:n])) <= 4e-16 * np.max(np.abs(ACC))
    # the 200 Hz channel at its own samples: every 5th grid point, the values written
    k = rec.native_samples("disp")
    assert np.array_equal(k, np.arange(0, n, 5))
    assert np.max(np.abs(rec.channels["disp"][k] - DISP)) <= 1e-15 * np.max(np.abs(DISP))
    # between them, a spline of the 2 Hz sine (the test can fail: the written values are 200 Hz samples)
    assert 0 < np.max(np.abs(rec.channels["disp"] - (0.004 + 0.012 * np.sin(4 * np.pi * rec.t + 0.3)))) < 1e-7


def test_the_files_hold_the_values_in_the_units_named(tmp_path):
    """Independent of read_record: the bytes written hold ACC / g and DISP / 1 mm with their units."""
    write_record(tmp_path / "run.h5", CHANNELS, units=UNITS, names=NAMES["h5"], start=START, comment="bench 3")
    with h5py.File(tmp_path / "run.h5", "r") as f:
        acc, disp = f["chassis/ACC FL-Z [raw]"], f["susp/Disp.FL (pot)"]
        assert np.array_equal(acc[()], ACC / G) and acc.attrs["unit"] == "g"
        assert np.array_equal(disp[()], DISP / 1e-3) and disp.attrs["unit"] == "mm"
        assert np.array_equal(f["t"][()], T1K) and np.array_equal(f["susp/t_Disp.FL (pot)"][()], T200)
        assert f.attrs["comment"] == "bench 3" and f.attrs["start"] == START.isoformat()
    write_record(tmp_path / "run.mat", CHANNELS, units=UNITS, names=NAMES["mat"])
    mat = scipy.io.loadmat(tmp_path / "run.mat", simplify_cells=True)
    assert np.array_equal(mat["DISP_FL_pot"], DISP / 1e-3) and np.array_equal(mat["t_DISP_FL_pot"], T200)
    assert mat["units"] == {"ACC_FL_Z": "g", "DISP_FL_pot": "mm"} and "t_ACC_FL_Z" not in mat
    from asammdf import MDF

    write_record(tmp_path / "run.mf4", CHANNELS, units=UNITS, names=NAMES["mf4"], start=START)
    with MDF(tmp_path / "run.mf4") as mdf:
        signal = mdf.get("Disp.FL (pot)")
        assert signal.unit == "mm" and np.array_equal(signal.samples, DISP / 1e-3)
        assert np.array_equal(signal.timestamps, T200)
        assert mdf.header.start_time.replace(tzinfo=None) == START


def test_a_single_rate_csv_reads_back_exactly_with_its_units_given(tmp_path):
    acc2 = -0.1 * G * np.cos(2 * np.pi * 5 * T1K)
    channels = {"acc": (T1K, ACC), "acc2": (T1K, acc2)}
    path = write_record(tmp_path / "run.csv", channels, units={"acc": "g"}, names={"acc": "ACC FL [g]"}, start=START)
    assert path.read_text().startswith(f"# start: {START.isoformat()}\n# units: ACC FL [g] [g], acc2 [SI]")
    rec = read_record(path, {"acc": "ACC FL [g]", "acc2": "acc2"}, {"acc": "g"}, resample=False)
    assert rec.t.size == 3000 and rec.rates == {"acc": 1000.0, "acc2": 1000.0}
    assert np.array_equal(rec.channels["acc"], ACC / G * G) and np.array_equal(rec.channels["acc2"], acc2)


def test_a_two_rate_csv_is_an_error_and_leaves_no_file(tmp_path):
    path = tmp_path / "run.csv"
    with pytest.raises(InputError, match=r"run\.csv.*one time column.*'acc'.*'disp'.*\.mf4"):
        write_record(path, CHANNELS)
    assert list(tmp_path.iterdir()) == []  # nothing written, no temporary left behind


def test_an_unknown_unit_is_an_error_naming_the_file_and_the_channel(tmp_path):
    with pytest.raises(InputError) as info:
        write_record(tmp_path / "run.mf4", CHANNELS, units={"disp": "mmm"}, names={"disp": "DISP_FL"})
    msg = str(info.value)
    for fragment in ("run.mf4", "'disp'", "'DISP_FL'", "'mmm'", "did you mean 'mm'"):
        assert fragment in msg, (fragment, msg)
    assert list(tmp_path.iterdir()) == []


def test_a_failed_write_keeps_the_old_file(tmp_path):
    path = write_record(tmp_path / "run.mat", CHANNELS, names=NAMES["mat"])
    before = path.read_bytes()
    with pytest.raises(InputError, match="'bad name'.*not a MATLAB name"):
        write_record(path, CHANNELS, names={"acc": "bad name"})
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["run.mat"]


@pytest.mark.parametrize(
    ("kw", "fragments"),
    [
        ({"names": {"acc": "X", "disp": "X"}}, ["'X'", "several channels"]),
        ({"names": {"acc": "t"}}, ["'acc'", "'t'"]),
        ({"units": {"speed": "m/s"}}, ["'speed'", "not a channel written"]),
    ],
)
def test_bad_names_are_errors_naming_the_channel(tmp_path, kw, fragments):
    with pytest.raises(InputError) as info:
        write_record(tmp_path / "run.h5", CHANNELS, **kw)
    for fragment in ["run.h5", *fragments]:
        assert fragment in str(info.value), (fragment, str(info.value))


def test_stamps_that_do_not_increase_and_an_unknown_suffix_are_errors(tmp_path):
    with pytest.raises(InputError, match=r"'disp'.*increase strictly"):
        write_record(tmp_path / "run.mf4", {"disp": (T200[::-1], DISP)})
    with pytest.raises(InputError, match=r"'\.xlsx'.*\.mf4"):
        write_record(tmp_path / "run.xlsx", CHANNELS)
