"""The logger format registry (vehid_cli/io/formats): every suffix has one format module with a reader and a writer,
listed in the order the messages give; a format registered by its decorator is found by suffix and nothing else."""

from __future__ import annotations

import numpy as np
import pytest

from vehid_cli.core.errors import InputError
from vehid_cli.io.formats import FORMATS, SUFFIXES, LoggerFormat, Raw, register, writable
from vehid_cli.io.read import read_record
from vehid_cli.io.write import write_record


def test_each_suffix_has_its_format_module():
    assert SUFFIXES == {
        ".csv": "csv", ".txt": "csv", ".mf4": "mdf", ".mdf": "mdf", ".mat": "mat", ".h5": "hdf5", ".hdf5": "hdf5",
    }  # fmt: skip
    assert writable() == [".csv", ".txt", ".mf4", ".mat", ".h5", ".hdf5"]
    modules = {fmt.name: type(fmt).__module__ for fmt in FORMATS.values()}
    assert modules == {
        "csv": "vehid_cli.io.formats.csv", "mdf": "vehid_cli.io.formats.mdf4",
        "mat": "vehid_cli.io.formats.mat", "hdf5": "vehid_cli.io.formats.hdf5",
    }  # fmt: skip
    for suffix, fmt in FORMATS.items():
        assert suffix in fmt.suffixes and set(fmt.writes) <= set(fmt.suffixes)


@pytest.fixture
def registry():
    """The registry as it is, restored after the test."""
    formats, suffixes = dict(FORMATS), dict(SUFFIXES)
    yield
    FORMATS.clear()
    FORMATS.update(formats)
    SUFFIXES.clear()
    SUFFIXES.update(suffixes)


def test_a_registered_format_is_read_and_written_by_suffix(registry, tmp_path):
    written = {}

    @register
    class Fake(LoggerFormat):
        name = "fake"
        suffixes = (".fake",)
        writes = (".fake",)
        rank = 15  # between csv and mdf in the messages

        def read(self, path, channels, *, time, rate, variable):
            return {ours: Raw(np.arange(5) / 10.0, np.arange(5.0), "mm") for ours in channels}

        def write(self, path, runs, names, units, *, start, comment):
            written.update(runs=runs, names=names, units=units)

    assert list(SUFFIXES)[:3] == [".csv", ".txt", ".fake"]
    (tmp_path / "run.fake").write_text("")
    rec = read_record(tmp_path / "run.fake", {"x": "X"})
    assert rec.rates == {"x": 10.0} and np.array_equal(rec.channels["x"], np.arange(5.0) * 1e-3)
    write_record(tmp_path / "run.fake", {"x": (np.arange(3.0), np.ones(3))}, units={"x": "mm"}, names={"x": "X"})
    assert written["names"] == {"x": "X"} and written["units"] == {"x": "mm"}
    assert np.array_equal(written["runs"]["x"][1], np.full(3, 1e3))
    with pytest.raises(InputError, match=r"expected one of \.csv, \.txt, \.fake, \.mf4"):
        read_record(tmp_path / "run.xlsx", {"x": "X"})


def test_a_suffix_owned_twice_is_refused(registry):
    with pytest.raises(ValueError, match="claimed"):

        @register
        class Other(LoggerFormat):
            name = "other"
            suffixes = (".csv",)
