"""Measurement files: reading the independent data, and a clear error for each kind of broken file."""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

import numpy as np
import pytest

import vehid_cli.core.files as files
from tests.conftest import VEHICLE_DATA, needs_shared
from vehid_cli.core.errors import DiskFull, InputError, WriteFailed
from vehid_cli.core.files import atomic_path, check_writable, check_writable_dir, write_bytes
from vehid_cli.io.measurement import format_rows, read_measurement, read_table, time_grid, write_measurement_csv


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


# ------------------------------------------------------------------------------------------ writing


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT], ids=["ENOSPC", "EDQUOT"])
def test_a_full_disk_is_disk_full_naming_the_file_and_leaves_no_temporary(tmp_path, monkeypatch, code):
    """Any write through atomic_path (here CSV text, and the bytes of an HDF5 image) that meets a full disk or
    quota raises DiskFull naming the target; the old content stays and the temporary is removed."""
    target = tmp_path / "m.csv"
    target.write_text("old content")

    def full(self, *args, **kwargs):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(Path, "write_text", full)
    t = time_grid(0.01, 1e-3)
    with pytest.raises(DiskFull) as caught:
        write_measurement_csv(target, t, np.zeros((t.size, 4)))
    assert str(caught.value) == f"no space left on device writing {target}"
    assert caught.value.errno == code and isinstance(caught.value, OSError)
    monkeypatch.undo()
    monkeypatch.setattr(files, "_write_bytes", lambda fh, b: full(None))
    with pytest.raises(DiskFull, match="m.csv"):
        write_bytes(target, b"new content")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv"] and target.read_text() == "old content"


def test_other_write_errors_are_not_disk_full(tmp_path):
    """A refused write (no permission, a read-only file system) is WriteFailed naming the file (exit 2), not a full
    disk; an I/O error of the disk stays what it is (exit 1)."""
    for code in (errno.EACCES, errno.EROFS):
        with pytest.raises(WriteFailed) as caught, atomic_path(tmp_path / "x.json"):
            raise OSError(code, os.strerror(code))
        assert not isinstance(caught.value, DiskFull) and caught.value.exit_code == 2
        assert str(caught.value) == f"cannot write {tmp_path / 'x.json'}: {os.strerror(code)}"
    with pytest.raises(OSError) as caught, atomic_path(tmp_path / "x.json"):
        raise OSError(errno.EIO, "Input/output error")
    assert not isinstance(caught.value, WriteFailed)
    assert list(tmp_path.iterdir()) == []


def test_stale_temporaries_of_the_target_are_removed_and_nothing_else(tmp_path):
    """A killed writer's `.NAME.*.tmp` goes at the next write of NAME; a live writer's (it holds the flock),
    other targets' temporaries and other files stay."""
    target = tmp_path / "x.csv"
    stale = tmp_path / ".x.csv.123.tmp"
    live = tmp_path / ".x.csv.k3j9x0aa.tmp"
    others = [".x.csv.bak.abcdefgh.tmp", ".y.csv.123.tmp", "x.csv.tmp", ".x.csv.partial", "x.csv.1.tmp"]
    for name in [stale.name, live.name, *others]:
        (tmp_path / name).write_text("left over")
    os.symlink(tmp_path / "x.csv.tmp", tmp_path / ".x.csv.link.tmp")  # our naming, but not a file we make
    os.mkfifo(tmp_path / ".x.csv.fifo.tmp")
    others += [".x.csv.link.tmp", ".x.csv.fifo.tmp"]
    fd = os.open(live, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # as atomic_path holds its temporary
        write_bytes(target, b"a,b\n")
        assert not stale.exists() and live.exists()
    finally:
        os.close(fd)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, "x.csv", *others])
    assert target.read_bytes() == b"a,b\n"
    write_bytes(target, b"c\n")  # the writer is gone (its lock released): now its temporary is stale
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["x.csv", *others])


# ------------------------------------------------------------------------------------------ separators


def european(text: str) -> str:
    """The same table as a European spreadsheet exports it: ';' between columns, ',' as decimal separator."""
    return text.replace(",", ";").replace(".", ",")


def test_semicolon_columns_with_decimal_commas_read_as_the_comma_file(tmp_path):
    t = time_grid(0.01, 1e-3)
    rng = np.random.default_rng(1)
    road, acc = rng.standard_normal((t.size, 4)), rng.standard_normal((t.size, 4)) * 1e3
    plain = tmp_path / "plain.csv"
    write_measurement_csv(plain, t, road, acc, comments=["exported"])
    text = plain.read_text()
    comma = write(tmp_path, european(text), "eu.csv")
    assert ";" in comma.read_text() and "0,001;" in comma.read_text()
    tab = write(tmp_path, text.replace(",", "\t").replace(".", ","), "tab.csv")
    a, b, c = read_measurement(plain), read_measurement(comma), read_measurement(tab)
    for m in (b, c):
        np.testing.assert_array_equal(m.t, a.t)
        np.testing.assert_array_equal(m.road, a.road)
        np.testing.assert_array_equal(m.acc, a.acc)


def test_semicolon_columns_with_decimal_points_read_too(tmp_path):
    path = write(tmp_path, "t;x\n0;1.5\n0.5;-2.25e-3\n")
    table = read_table(path)
    assert table.column("x").tolist() == [1.5, -2.25e-3]


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("t,x,f\n0,1,0,2\n", "line 2 has 4 fields, the header has 3 (t, x, f; separated by ',')"),
        ("t;x;f\n0;1,234,5;2\n", "column 'x', line 2: expected a number, got '1,234,5'"),
        ("t;x;f\n0;1.234,5;2\n", "column 'x', line 2: expected a number, got '1.234,5'"),
    ],
)
def test_a_decimal_comma_that_cannot_be_read_is_refused_naming_file_line_and_column(tmp_path, text, fragment):
    path = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        read_table(path)
    message = str(info.value)
    assert message.startswith(str(path)) and fragment in message, message
    assert "decimal comma? use '.' as the decimal separator, or ';'-separated columns" in message


# ------------------------------------------------------------------------------------------ exact, short numbers


def test_written_values_are_the_shortest_repr_that_reads_back_exactly(tmp_path):
    t = time_grid(1.0, 1e-3)  # 3 * 0.001 is 0.0030000000000000001 in %.17g
    rng = np.random.default_rng(2)
    road, disp = rng.standard_normal((t.size, 4)) * 1e-3, rng.standard_normal((t.size, 4))
    path = tmp_path / "m.csv"
    write_measurement_csv(path, t, road, disp=disp)
    lines = path.read_text().splitlines()
    written_t = [line.split(",")[0] for line in lines[1:]]
    assert written_t == [repr(float(x)) for x in t]
    assert written_t[3] == "0.003" and written_t[:2] == ["0.0", "0.001"]
    m = read_measurement(path)
    np.testing.assert_array_equal(m.t, t)
    np.testing.assert_array_equal(m.road, road)
    np.testing.assert_array_equal(m.disp, disp)
    assert lines[5].split(",")[1:] == [repr(float(x)) for x in road[4]] + [repr(float(x)) for x in disp[4]]


def test_format_rows_keeps_specials_and_extremes():
    values = np.array([[0.1, -0.0, 1e-300, 5e-324, 1.7976931348623157e308, np.nan, np.inf]])
    text = format_rows(values)
    assert text == "0.1,-0.0,1e-300,5e-324,1.7976931348623157e+308,nan,inf\n"
    back = np.array([float(x) for x in text.strip().split(",")])
    np.testing.assert_array_equal(back, values[0])


# ------------------------------------------------------------------------------------------ output directories


def test_check_writable_dir_leaves_nothing_and_names_option_and_path(tmp_path):
    new = tmp_path / "a" / "b"
    assert check_writable_dir(new, "--plots") == new
    assert not (tmp_path / "a").exists() and list(tmp_path.iterdir()) == []  # probed, nothing made or left
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=r"^--plots .*/f/sub: cannot create the directory: '.*/f' is a file"):
        check_writable_dir(tmp_path / "f" / "sub", "--plots")
    with pytest.raises(InputError, match=r"^-o .*/f: is a file, expected a directory"):
        check_writable_dir(tmp_path / "f", "-o")
    if os.geteuid() != 0:  # root writes through chmod
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        with pytest.raises(InputError, match=r"ro/new: cannot write in '.*ro' \(to create the directory in\)"):
            check_writable_dir(ro / "new", "--plots")


def test_check_writable_names_a_file_in_the_way(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=r"f/out.json: output directory '.*/f' is a file, not a directory"):
        check_writable(tmp_path / "f" / "out.json", (".json",))
