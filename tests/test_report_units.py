"""Issue 23, acceptance 3: every table format shows each parameter's unit and its 95 % interval, rounded to it, for a
simulated campaign and for one fit on measured data (and a damper's campaign); the JSON has `units` and `ci95` at
full precision, and an estimate on a bound is marked in every format. Each format is parsed (the terminal text, md,
LaTeX, CSV with the csv module, JSON) and checked against the JSON's full-precision numbers."""

from __future__ import annotations

import csv
import io
import json
import math

import pytest

from tests.conftest import BASE_CONFIG, ROOT, SMALL, invoke, sets

Z95 = 1.959963984540054
CAR_UNITS = {"m": "kg", "Ix": "kg m²", "Iy": "kg m²", "a1": "m", "b1": "m"}  # SPEC section 1's SI units
LATEX_UNITS = {"kg": "kg", "kg m²": "kg m$^2$", "m": "m", "N/m": "N/m", "N s/m": "N s/m", "N": "N"}


def last_digit(half: str) -> float:
    """The value of the last digit a rounded uncertainty shows ('12' -> 1, '0.00067' -> 1e-5, '3.0e+05' -> 1e4,
    '270' -> 10: two significant digits)."""
    if "e" in half:
        mantissa, exponent = half.split("e")
        return 10.0 ** (int(exponent) - len(mantissa.partition(".")[2]))
    if "." in half:
        return 10.0 ** -len(half.partition(".")[2])
    return 10.0 ** (math.floor(math.log10(float(half))) - 1)


def check_rounded(text: str, value: float, half: float) -> None:
    """'v ± h' is the full value and half-width rounded to two significant digits of the half-width."""
    v, h = text.split(" ± ")
    last = last_digit(h)
    assert abs(float(v) - value) <= 0.5 * last * (1 + 1e-9), (text, value)
    assert abs(float(h) - half) <= 0.5 * last * (1 + 1e-9), (text, half)
    assert 10 * last <= float(h) * (1 + 1e-9) < 1000 * last  # two (or, rounded up a decade, three) digits


def check_interval(text: str, low: float, high: float) -> None:
    """'[lo, hi]' is the full interval rounded to two significant digits of its half-width."""
    lo, hi = text.strip("[]").split(", ")
    last = 10.0 ** (math.floor(math.log10((high - low) / 2)) - 1)
    assert abs(float(lo) - low) <= 0.5 * last * (1 + 1e-9) and abs(float(hi) - high) <= 0.5 * last * (1 + 1e-9)


def report(path, fmt: str) -> str:
    code, out, err = invoke("report", path, "--format", fmt)
    assert code == 0, err
    return out


def text_rows(text: str) -> dict[str, list[str]]:
    """The rows of the terminal tables (plain text): {first cell: cells}."""
    rows = {}
    for line in text.splitlines():
        if line.startswith("│"):
            cells = [c.strip() for c in line.strip("│").split("│")]
            rows[cells[0]] = cells
    return rows


def md_rows(text: str) -> dict[str, list[str]]:
    return {c[0]: c for c in ([x.strip() for x in line.strip("|").split("|")] for line in text.splitlines()
                              if line.startswith("| "))}  # fmt: skip


def latex_rows(text: str) -> dict[str, list[str]]:
    return {c[0]: c for c in ([x.strip() for x in line.removesuffix(r" \\").split(" & ")] for line in text.splitlines()
                              if line.endswith(r" \\"))}  # fmt: skip


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A simulated campaign of the car (4 runs), one fit of the car on a simulated measurement file, one with m
    forced onto a bound, and a damper campaign: their results files and JSON."""
    d = tmp_path_factory.mktemp("units")
    small = sets(SMALL[:2])
    code, _, err = invoke("identify", BASE_CONFIG, *sets(SMALL), "-o", d / "sim.h5", "--json", d / "sim.json")
    assert code == 0, err
    code, _, err = invoke("simulate", BASE_CONFIG, *small, "-o", d / "run.csv", "--set", "noise.level=0.05")
    assert code == 0, err
    fit = [*small, *sets(["noise.level=0", "identify.algorithm.name=lsq", "identify.start=config"])]
    code, _, err = invoke("identify", BASE_CONFIG, "--data", d / "run.csv", *fit, "-o", d / "fit.h5", "--json",
                          d / "fit.json")  # fmt: skip
    assert code == 0, err
    at_bound = [*fit, *sets(["vehicle.m=1150", "identify.limits.m=[1000,1200]"])]  # the data's m is 1300
    code, _, err = invoke("identify", BASE_CONFIG, "--data", d / "run.csv", *at_bound, "-o", d / "bound.h5",
                          "--json", d / "bound.json")  # fmt: skip
    assert code == 0, err
    damper = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
    code, _, err = invoke("identify", damper, "--runs", "3", "--jobs", "1", *sets(["identify.budget=60"]), "-o",
                          d / "damper.h5", "--json", d / "damper.json")  # fmt: skip
    assert code == 0, err
    return d


@pytest.mark.parametrize("name", ["sim", "fit"])
def test_json_has_units_and_the_95_percent_interval_at_full_precision(files, name):
    doc = json.loads((files / f"{name}.json").read_text())
    assert doc["units"] == CAR_UNITS
    report_doc = json.loads(report(files / f"{name}.h5", "json"))[0]  # the report's JSON: the same, read back
    assert report_doc["units"] == CAR_UNITS and report_doc["ci95"] == doc["ci95"]
    for p in doc["parameters"]:
        low, high = doc["ci95"][p]
        assert low < doc["mean"][p] < high
        assert (high - low) / 2 == pytest.approx(Z95 * (doc["crlb"]["sd"][p] if name == "fit" else sd(files, p)))
    assert doc["ci95_from"] == {"sim": "runs", "fit": "bound"}[name]


def sd(files, parameter: str) -> float:
    """The spread over runs of a parameter, straight from the campaign file."""
    import h5py
    import numpy as np

    with h5py.File(files / "sim.h5", "r") as h5:
        names = [n.decode() if isinstance(n, bytes) else n for n in h5["parameters"][()]]
        assert json.loads(h5["parameters"].attrs["units"]) == [CAR_UNITS[n] for n in names]
        return float(np.std(h5["runs/estimate"][:, names.index(parameter)], ddof=1))


@pytest.mark.parametrize("name", ["sim", "fit"])
def test_terminal_markdown_and_latex_tables_show_units_and_the_interval_rounded_to_it(files, name):
    doc = json.loads((files / f"{name}.json").read_text())
    md, tex = md_rows(report(files / f"{name}.h5", "md")), latex_rows(report(files / f"{name}.h5", "latex"))
    code, _, err = invoke("report", files / f"{name}.h5", "-o", files / f"{name}.txt")
    assert code == 0, err
    table = text_rows((files / f"{name}.txt").read_text())
    est_column = {"sim": "mean ± 95 %", "fit": "estimate ± 95 %"}[name]
    assert est_column in (files / f"{name}.txt").read_text()
    for p, unit in CAR_UNITS.items():
        low, high = doc["ci95"][p]
        value, half = (low + high) / 2, (high - low) / 2
        assert doc["mean"][p] == pytest.approx(value)
        assert table[p][1] == unit and md[p][1] == unit and tex[p][1] == LATEX_UNITS[unit]
        check_rounded(table[p][3], value, half)
        check_rounded(md[p][3], value, half)
        check_rounded(tex[p][3].replace(r" $\pm$ ", " ± "), value, half)


def test_csv_keeps_full_precision_with_units_and_the_interval(files):
    for name in ("sim", "fit"):
        doc = json.loads((files / f"{name}.json").read_text())
        rows = {r["parameter"]: r for r in csv.DictReader(io.StringIO(report(files / f"{name}.h5", "csv")))}
        for p, unit in CAR_UNITS.items():
            r = rows[p]
            assert r["unit"] == unit and r["ci95_from"] == doc["ci95_from"] and r["at_bound_runs"] == "0"
            assert [float(r["ci95_low"]), float(r["ci95_high"])] == doc["ci95"][p]  # every digit
            assert float(r["mean"]) == doc["mean"][p]


def test_an_estimate_on_a_bound_is_marked_in_every_format(files):
    doc = json.loads((files / "bound.json").read_text())
    assert doc["at_bound"] == ["m"] and doc["ci95"]["m"] is None and doc["mean"]["m"] == pytest.approx(1200)
    assert all(doc["ci95"][p] is not None for p in CAR_UNITS if p != "m")
    code, _, err = invoke("report", files / "bound.h5", "-o", files / "bound.txt")
    assert code == 0, err
    table = text_rows((files / "bound.txt").read_text())
    md, tex = md_rows(report(files / "bound.h5", "md")), latex_rows(report(files / "bound.h5", "latex"))
    assert "m AT BOUND" in table and table["m AT BOUND"][3] == "1200 AT BOUND"
    assert "AT BOUND" in md["m"][3] and "AT BOUND" in tex["m"][3] and "±" not in md["m"][3]
    rows = {r["parameter"]: r for r in csv.DictReader(io.StringIO(report(files / "bound.h5", "csv")))}
    assert rows["m"]["at_bound_runs"] == "1" and rows["m"]["ci95_low"] == "nan"


def test_a_damper_campaign_shows_its_model_units_in_every_format(files):
    doc = json.loads((files / "damper.json").read_text())
    units = {"k1": "N/m", "c0": "N s/m", "fc": "N"}
    assert doc["units"] == units
    assert set(doc["model_row_units"]) == set(doc["model_row"]) and doc["model_row_units"]["v_eps"] == "m/s"
    md = md_rows(report(files / "damper.h5", "md"))
    tex = latex_rows(report(files / "damper.h5", "latex"))
    rows = {r["parameter"]: r for r in csv.DictReader(io.StringIO(report(files / "damper.h5", "csv")))}
    for p, unit in units.items():
        low, high = doc["ci95"][p]
        assert md[p][1] == unit and tex[p][1] == unit and rows[p]["unit"] == unit
        check_rounded(md[p][3], (low + high) / 2, (high - low) / 2)
        check_interval(md[p][4], low, high)
        check_rounded(tex[p][3].replace(r" $\pm$ ", " ± "), (low + high) / 2, (high - low) / 2)
        assert [float(rows[p]["ci95_low"]), float(rows[p]["ci95_high"])] == doc["ci95"][p]


def test_a_file_written_before_units_were_recorded_reads_with_the_configs_units(files, tmp_path):
    """Older campaign files have no /parameters attribute `units`: the config's declarations give them; a file's own
    record wins over them; a record that does not name one unit per unknown is a damaged file (exit 2)."""
    import shutil

    import h5py

    from vehid_cli.campaign.results import read_campaign_h5
    from vehid_cli.core.store import stamp_checksum

    def edited(name: str, units: list[str] | None):
        path = tmp_path / f"{name}.h5"
        shutil.copy(files / "sim.h5", path)
        with h5py.File(path, "r+") as h5:
            del h5["parameters"].attrs["units"]
            if units is not None:
                h5["parameters"].attrs["units"] = json.dumps(units)
        stamp_checksum(path)
        return path

    old = read_campaign_h5(edited("old", None))
    assert old.stored_units == () and old.units == CAR_UNITS
    assert json.loads(report(tmp_path / "old.h5", "json"))[0]["units"] == CAR_UNITS
    own = read_campaign_h5(edited("own", ["t", "t m²", "t m²", "mm", "mm"]))  # made up, to tell them apart
    assert own.units["m"] == "t" and own.units["a1"] == "mm"
    code, _, err = invoke("report", edited("short", ["kg"]), "--format", "json")
    assert code == 2 and "attribute 'units' of /parameters names 1 units for 5 unknowns" in err
