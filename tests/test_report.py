"""Reports: every format from real campaign files, the figures, the published values."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
import yaml

from tests.conftest import BASE_CONFIG, ROOT, cli, read_png, vehid
from vehid_cli.campaign.results import read_campaign_h5, write_campaign_h5
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.config import load_config
from vehid_cli.report.campaigns import load_published, render
from vehid_cli.systems.vehicle.report import CSV_COLUMNS

SMALL = [
    "simulation.duration=1.5", "simulation.dt=0.002", "identify.runs=3",
    "identify.algorithm.population=6", "identify.algorithm.iterations=4",
]  # fmt: skip
PAPER = ROOT / "configs" / "gokdag2015" / "paper_tables.yaml"


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("campaigns")
    for name in ("abc", "cpso"):
        cfg = load_config(BASE_CONFIG, SMALL + [f"identify.algorithm.name={name}", "identify.objective=f1"])
        write_campaign_h5(d / f"{name}.h5", run_campaign(cfg, jobs=1))
    return d


def read_all(d):
    files = sorted(str(p) for p in d.glob("*.h5"))
    return [read_campaign_h5(f) for f in files], files


def test_markdown_puts_algorithms_side_by_side_with_published_values(campaign_dir):
    campaigns, files = read_all(campaign_dir)
    text = render(campaigns, files, "md", load_published(PAPER))
    assert text.count("**objective f1") == 1  # one group: same objective and noise
    header = next(line for line in text.splitlines() if line.startswith("| parameter | unit | true"))
    assert "abc est ± 95 %" in header and "cpso RE %" in header and "abc paper RE %" in header
    assert "| Ix | kg m² | 500 |" in text
    nre_row = next(line for line in text.splitlines() if line.startswith("| NRE of mean %"))
    cells = [c.strip() for c in nre_row.strip("|").split("|")]
    assert cells[header.strip("|").split("|").index(" abc paper RE % ")] == "0.729"  # the paper's ABC, f1, 10 %


def test_csv_is_long_format_with_computed_numbers(campaign_dir):
    campaigns, files = read_all(campaign_dir)
    rows = list(csv.DictReader(io.StringIO(render(campaigns, files, "csv"))))
    assert list(rows[0]) == list(CSV_COLUMNS)
    assert len(rows) == 2 * 5
    c = campaigns[0]
    first = rows[0]
    assert float(first["mean"]) == pytest.approx(c.summary.mean[0])
    assert float(first["nre_percent"]) == pytest.approx(c.summary.nre_percent)


def test_latex_and_json(campaign_dir):
    campaigns, files = read_all(campaign_dir)
    tex = render(campaigns, files, "latex")
    assert "\\toprule" in tex and "\\bottomrule" in tex and "\\%" in tex
    docs = json.loads(render(campaigns, files, "json"))
    assert [d["file"] for d in docs] == files
    assert all(d["runs"] == 3 and len(d["per_run_nre_percent"]) == 3 for d in docs)


def test_report_cli_tables_and_plots(campaign_dir, tmp_path):
    res = vehid("report", campaign_dir, "--plots", tmp_path / "fig")
    assert res.returncode == 0, res.stderr
    assert "NRE of mean" in res.stdout
    pngs = sorted(p.name for p in (tmp_path / "fig").glob("*.png"))
    assert "convergence_f1_both_np0.1.png" in pngs and "re_boxes_f1_both_np0.1.png" in pngs
    assert sum(name.startswith("true_vs_estimated") for name in pngs) == 2
    for name in pngs:
        read_png(tmp_path / "fig" / name)


def test_report_rejects_a_file_that_is_not_a_campaign(tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    res = vehid("report", bad)
    assert res.returncode == 2 and "bad.h5" in res.stderr and "Traceback" not in res.stderr


def test_published_tables_are_consistent():
    """Each published NRE is the norm of its printed RE column, and each RE matches its estimate (to print
    precision), except the one oddity the file documents (GA, f2, Np = 20 %, Iy)."""
    doc = yaml.safe_load(PAPER.read_text())
    truth = doc["truth"]
    for table in doc["tables"]:
        for algorithm in ("ga", "cpso", "abc"):
            col = table[algorithm]
            re = np.array([col["re"][n] for n in truth])
            assert np.linalg.norm(re) == pytest.approx(col["nre"], abs=0.006)
            for n, t in truth.items():
                if (table["objective"], table["noise_level"], algorithm, n) == ("f2", 0.2, "ga", "Iy"):
                    continue
                implied = 100 * (col["est"][n] - t) / t
                assert implied == pytest.approx(col["re"][n], abs=0.5 + 0.05 * abs(col["re"][n]))


def test_table_format_writes_to_a_file_and_directories_skip_other_h5(campaign_dir, tmp_path):
    sim = campaign_dir / "zz_simulation.h5"
    made = vehid("simulate", BASE_CONFIG, "-o", sim)
    assert made.returncode == 0, made.stderr
    try:
        res = vehid("report", campaign_dir, "-o", tmp_path / "t.txt")
        assert res.returncode == 0, res.stderr
        text = (tmp_path / "t.txt").read_text()
        assert text.count("NRE of mean") == 2  # the two campaigns; the simulation file is not one
    finally:
        sim.unlink()


# ------------------------------------------------------------------------------------------ --format and -o


def test_the_cli_knows_the_report_formats():
    from vehid_cli.cli.report import REPORT_FORMATS, REPORT_SUFFIXES
    from vehid_cli.report.campaigns import FORMATS

    assert REPORT_FORMATS == FORMATS and set(REPORT_SUFFIXES.values()) == set(FORMATS)


@pytest.mark.parametrize(
    "name, fmt, check",
    [
        ("r.latex", None, lambda text: "\\toprule" in text),
        ("r.tex", "latex", lambda text: "\\toprule" in text),
        ("r.md", None, lambda text: "|---|" in text and "\\toprule" not in text),
        ("r.json", None, lambda text: len(json.loads(text)) == 2),
        ("r.csv", None, lambda text: next(csv.reader(io.StringIO(text)))[: len(CSV_COLUMNS)] == list(CSV_COLUMNS)),
        ("r.txt", None, lambda text: text.count("NRE of mean") == 2),
    ],
)
def test_report_format_follows_the_output_suffix(campaign_dir, tmp_path, name, fmt, check):
    out = tmp_path / name
    res = cli("report", campaign_dir, "-o", out, *(["--format", fmt] if fmt else []))
    assert res.exit_code == 0, res.output
    assert check(out.read_text()), out.read_text()[:300]


def test_report_format_and_suffix_that_disagree_are_refused(campaign_dir, tmp_path):
    res = cli("report", campaign_dir, "--format", "md", "-o", tmp_path / "x.csv")
    assert res.exit_code == 2
    assert "--format md disagrees with -o" in res.stderr and "x.csv" in res.stderr and "as csv" in res.stderr
    res = cli("report", campaign_dir, "-o", tmp_path / "x.html")
    assert res.exit_code == 2
    assert "x.html" in res.stderr and "suffix '.html'" in res.stderr and ".tex (latex)" in res.stderr
    res = cli("report", campaign_dir, "--format", "html")
    assert res.stderr == "error: --format must be one of table, md, csv, latex, json, got 'html'\n"
    assert list(tmp_path.iterdir()) == []


def test_report_plots_directory_is_checked_before_any_work(campaign_dir, tmp_path):
    (tmp_path / "somefile").write_text("x")
    target = tmp_path / "somefile" / "figs"
    res = cli("report", campaign_dir, "--plots", target)
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith(f"error: --plots {target}: cannot create the directory"), res.stderr
    assert "NRE of mean" not in res.stdout  # refused before the tables


def test_sweep_notes_tell_a_running_campaign_from_an_interrupted_one(tmp_path):
    from vehid_cli.core.locking import exclusive
    from vehid_cli.report.campaigns import sweep_notes

    (tmp_path / "a.h5.partial").mkdir()
    (tmp_path / "a.h5.partial" / "run-00000.npz").write_bytes(b"")
    (tmp_path / "b.h5.partial").mkdir()
    with exclusive(tmp_path / "a.h5"):  # what the process running a.h5's campaign holds
        notes = sweep_notes([tmp_path])
    assert any("a.h5.partial: a campaign running now (1 finished run(s) so far)" in n for n in notes), notes
    assert any("b.h5.partial: an interrupted campaign (0 finished run(s))" in n for n in notes), notes


@pytest.mark.parametrize("width", [80, 60])
def test_force_map_parameter_names_are_whole_in_a_narrow_terminal(width):
    """Issue 23: in 80 columns (a pipe, a CI log) the force-map damper's table cut `tau_comp_rise` to `tau_comp_…`
    and its estimates to `0.00812…`. Names are now never cut, numbers whole where they fit and folded where not: no
    ellipsis anywhere, every name on a line of its own, and the table no wider than the console."""
    from rich.console import Console

    from vehid_cli.report.campaigns import rich_tables

    config = ROOT / "configs" / "dampers" / "synthetic_force_map_steps.yaml"
    campaign = run_campaign(load_config(config, ["identify.runs=1", "identify.budget=5"]), jobs=1)
    console = Console(width=width, record=True, file=io.StringIO())
    for table in rich_tables([campaign], ["fmap.h5"]):
        console.print(table)
    text = console.export_text()
    assert "…" not in text
    cells = {line.split("│")[1].strip() for line in text.splitlines() if line.startswith("│")}
    assert set(campaign.names) <= cells
    assert max(len(line) for line in text.splitlines()) <= width
