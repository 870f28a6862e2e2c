"""Measurement files: reading the independent data, and a clear error for each kind of broken file."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import VEHICLE_DATA, needs_shared
from vehid_cli.data import read_measurement, read_table, time_grid, write_measurement_csv
from vehid_cli.errors import InputError


def test_reads_the_shared_bump_run():
    m = read_measurement(needs_shared(VEHICLE_DATA / "bump_run_A.csv"))
    assert m.t.size == 3000 and m.dt == pytest.approx(1e-3)
    assert m.road.shape == m.acc.shape == m.disp.shape == (3000, 4)
    assert m.road[-1].tolist() == pytest.approx([0.05, 0.04, 0.04, 0.05])


def test_round_trip_keeps_full_precision(tmp_path):
    t = time_grid(0.5, 1e-3)
    rng = np.random.default_rng(0)
    road, acc, disp = (rng.standard_normal((t.size, 4)) for _ in range(3))
    path = tmp_path / "m.csv"
    write_measurement_csv(path, t, road, acc, disp, comments=["made by a test", "two\nlines"])
    m = read_measurement(path)
    np.testing.assert_array_equal(m.acc, acc)
    np.testing.assert_array_equal(m.disp, disp)
    np.testing.assert_array_equal(m.road, road)
    assert [p.name for p in tmp_path.iterdir()] == ["m.csv"]  # no temporary file left


def write(tmp_path, text, name="m.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


HEADER = "t,road1,road2,road3,road4,acc1,acc2,acc3,acc4\n"


def rows(times, extra=""):
    return "".join(f"{t},0,0,0,0,1,2,3,4{extra}\n" for t in times)


@pytest.mark.parametrize(
    "text, fragment",
    [
        (HEADER + rows([0, 0.001, 0.0025, 0.003]), "not uniformly sampled"),
        (HEADER + rows([0, 0.002, 0.001, 0.003]), "must increase strictly"),
        ("t,road1,road2,road4,acc1,acc2,acc3,acc4\n" + "".join(f"{k},0,0,0,1,2,3,4\n" for k in range(3)), "road3"),
        ("t,road1,road2,road3,road4,acc1,acc2,acc3\n" + "".join(f"{k},0,0,0,0,1,2,3\n" for k in range(3)), "acc4"),
        ("t,road1,road2,road3,road4\n0,0,0,0,0\n0.1,0,0,0,0\n0.2,0,0,0,0\n", "no response columns"),
        (HEADER + "0,0,0,0,0,1,2,3,4\n0.001,0,0,0,0,nan,2,3,4\n0.002,0,0,0,0,1,2,3,4\n", "column 'acc1'"),
        (HEADER + "0,0,0,0,0,1,2,3,4\n0.001,0,0,0,0,x,2,3,4\n", "column 'acc1', line 3"),
        (HEADER + "0,0,0,0,0,1,2,3\n", "line 2 has 8 fields"),
        ("", "empty file"),
        ("# only a comment\n", "empty file"),
        (HEADER, "no data rows"),
        (HEADER + rows([0, 0.001]), "at least 3"),
    ],
)
def test_broken_files_name_the_problem(tmp_path, text, fragment):
    path = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        read_measurement(path)
    assert fragment in str(info.value) and str(path) in str(info.value)


def test_unreadable_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_table(tmp_path / "missing.csv")
    with pytest.raises(InputError, match="is a directory"):
        read_table(tmp_path)
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError, match="cannot read"):
        read_table(binary)


def test_printing_roundoff_in_time_is_tolerated(tmp_path):
    times = [round(k * 0.001, 6) + (1e-9 if k % 2 else 0) for k in range(10)]
    m = read_measurement(write(tmp_path, HEADER + rows(times)))
    assert m.dt == pytest.approx(0.001)


def test_byte_order_mark_is_tolerated(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + (HEADER + rows([0, 0.001, 0.002])).encode())
    assert read_measurement(path).t.size == 3
