"""Measurement files: reading the independent data, and a clear error for each kind of broken file."""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import VEHICLE_DATA, needs_shared
from vehid_cli import data
from vehid_cli.data import atomic_path, read_measurement, read_table, time_grid, write_bytes, write_measurement_csv
from vehid_cli.errors import DiskFull, InputError


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
    monkeypatch.setattr(data, "_write_bytes", lambda fh, b: full(None))
    with pytest.raises(DiskFull, match="m.csv"):
        write_bytes(target, b"new content")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv"] and target.read_text() == "old content"


def test_other_write_errors_are_not_disk_full(tmp_path):
    with pytest.raises(PermissionError), atomic_path(tmp_path / "x.json"):
        raise PermissionError(errno.EACCES, "denied")
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
