"""The result protocol (core/result.py, core/store.py): every kind of field to JSON, into a checksummed file and back;
a damaged file refused naming it; the damper's findings through their campaign-file group unchanged."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import pytest
from numpy.typing import NDArray

from vehid_cli.core.errors import InputError
from vehid_cli.core.jsonio import to_json
from vehid_cli.core.result import Result
from vehid_cli.core.store import USERBLOCK, load, save
from vehid_cli.systems.damper.findings import Findings, Trace
from vehid_cli.systems.damper.fit import RealTime


@dataclass(frozen=True)
class Inner(Result):
    label: str
    values: NDArray


@dataclass(frozen=True)
class Outer(Result):
    name: str
    count: int
    ratio: float
    ok: bool
    names: tuple[str, ...]
    matrix: NDArray
    inner: Inner
    parts: tuple[Inner, ...]
    table: dict[str, float] = field(default_factory=dict)


def outer() -> Outer:
    rng = np.random.default_rng(3)
    return Outer(
        "toy", 7, 0.1 + 0.2, True, ("a", "b"), rng.standard_normal((3, 2)), Inner("in", np.arange(4.0)),
        (Inner("p0", np.array([np.nan, 1.5])), Inner("p1", np.zeros(0))), {"x": 2.5, "y": -1.0},
    )  # fmt: skip


def test_every_kind_of_field_round_trips_through_a_checksummed_file(tmp_path):
    path = tmp_path / "toy.h5"
    original = outer()
    save(path, "vehid.toy", original, attrs={"note": "a test"})
    back = load(path, "vehid.toy", Outer)
    assert (back.name, back.count, back.ok, back.names, back.table) == ("toy", 7, True, ("a", "b"), original.table)
    assert back.ratio == original.ratio  # bit for bit: 0.30000000000000004
    np.testing.assert_array_equal(back.matrix, original.matrix)
    assert back.inner.label == "in" and [p.label for p in back.parts] == ["p0", "p1"]
    np.testing.assert_array_equal(back.parts[0].values, original.parts[0].values)  # NaN kept
    assert back.parts[1].values.shape == (0,)


def test_json_is_plain_data_and_strict():
    doc = json.loads(to_json(outer().to_json()))
    assert doc["names"] == ["a", "b"] and doc["inner"]["values"] == [0.0, 1.0, 2.0, 3.0]
    assert doc["parts"][0]["values"] == [None, 1.5]  # NaN is null
    assert doc["count"] == 7 and doc["ok"] is True and len(doc["matrix"]) == 3


def test_a_damaged_or_foreign_file_is_refused_naming_it(tmp_path):
    path = tmp_path / "toy.h5"
    save(path, "vehid.toy", outer())
    data = bytearray(path.read_bytes())
    data[USERBLOCK + 200] ^= 0xFF
    damaged = tmp_path / "damaged.h5"
    damaged.write_bytes(bytes(data))
    with pytest.raises(InputError, match="damaged"):
        load(damaged, "vehid.toy", Outer)
    with pytest.raises(InputError, match="not a vehid"):
        load(path, "vehid.campaign", Outer)


def test_the_damper_findings_keep_their_group_and_read_back_whole(tmp_path):
    import h5py

    t = np.linspace(0, 1, 5)
    findings = Findings(
        "bingham", ("k1", "c0"), np.array([2000.0, 1500.0]), (("held.csv", 0.25),),
        RealTime("bingham", 1e-3, True, 40.0, 8e-3), (Trace("train:a", t, t, t, t * 2, t * 3, 0.125),),
    )  # fmt: skip
    path = tmp_path / "f.h5"
    with h5py.File(path, "w") as h5:
        findings.write_h5(h5.create_group("damper"))
    with h5py.File(path, "r") as h5:
        g = h5["damper"]
        assert set(g) == {"model_names", "model_values", "validation", "realtime", "traces"}
        assert set(g["realtime"].attrs) == {"dt", "stable", "realtime_factor", "largest_stable_dt"}
        assert set(g["traces/00"]) == {"t", "x", "v", "measured", "model"}
        back = Findings.read_h5(g)
    assert back.realtime == findings.realtime and back.validation == findings.validation
    assert back.names == findings.names and back.traces[0].J == 0.125 and back.traces[0].name == "train:a"
    np.testing.assert_array_equal(back.traces[0].model, t * 3)
