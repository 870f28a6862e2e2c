"""`vehid report --html`: one self-contained page (SPEC section 6), opened in a real headless browser (Debian's
chromium and chromium-driver through selenium; `make test` installs them): the tables render with the parameter
names, every figure decodes, nothing is fetched from outside and the console stays clean."""

from __future__ import annotations

import json
import os
import re
import shutil
from html.parser import HTMLParser

import pytest

from tests.conftest import BASE_CONFIG, ROOT, cli
from vehid_cli.campaign.results import read_campaign_h5, write_campaign_h5
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.config import load_config
from vehid_cli.report.html import Section, page, table_html
from vehid_cli.systems import VehicleSystem, system_class

SHORT = ["simulation.duration=1.5", "simulation.dt=0.002"]
DAMPER = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
FIT = SHORT + [
    "identify.algorithm.name=lsq", "identify.objective=wls", "noise.level=0", "identify.start=config",
    "identify.unknowns=[m, Iy, a1]",
]  # fmt: skip
SIMULATED = SHORT + ["identify.runs=3", "identify.algorithm.name=de", "identify.algorithm.population=6",
                     "identify.algorithm.iterations=3"]  # fmt: skip


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    """A measured-data campaign of the car (one fit), a simulated one (3 runs) and a damper's fit on a bench run,
    each reported as a page by the CLI."""
    d = tmp_path_factory.mktemp("html")
    truth = load_config(BASE_CONFIG, SHORT + ["vehicle.m=1450", "noise.level=0.02"])
    VehicleSystem.write_simulation(truth, d / "run.csv", seed=5)
    write_campaign_h5(d / "fit.h5", run_campaign(load_config(BASE_CONFIG, FIT), d / "run.csv", jobs=1))
    write_campaign_h5(d / "sim.h5", run_campaign(load_config(BASE_CONFIG, SIMULATED), jobs=1))
    bench = load_config(DAMPER)
    system_class(bench).write_simulation(bench, d / "bench.csv", seed=1)
    write_campaign_h5(d / "damper.h5", run_campaign(bench, d / "bench.csv", jobs=1))
    out = {}
    for stem in ("fit", "sim", "damper"):
        res = cli("report", d / f"{stem}.h5", "--html", d / f"{stem}.html")
        assert res.exit_code == 0, res.output
        assert res.stdout.strip() == f"wrote {d / f'{stem}.html'}"  # the page only: no tables on the terminal
        out[stem] = d / f"{stem}.html"
    sets = [x for s in SHORT for x in ("--set", s)]
    res = cli("diagnose", BASE_CONFIG, "--data", d / "run.csv", *sets, "--json", d / "diagnose.json",
              "--html", d / "diagnose.html")  # fmt: skip
    assert res.exit_code == 0, res.output
    out["diagnose"] = d / "diagnose.html"
    return d, out


def names_of(d, stem) -> tuple[str, ...]:
    """The parameter names a page must show in its tables."""
    if stem == "diagnose":
        return tuple(json.loads((d / "diagnose.json").read_text())["after"]["estimates"])
    return read_campaign_h5(d / f"{stem}.h5").names


class _Elements(HTMLParser):
    """Tags and attributes of a page, and the text of its table cells."""

    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.cells: list[str] = []
        self._cell = None

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))
        if tag in ("td", "th"):
            self._cell = ""

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.cells.append(self._cell)
            self._cell = None


def parse(path) -> _Elements:
    p = _Elements()
    p.feed(path.read_text(encoding="utf-8"))
    return p


def test_the_page_is_self_contained_with_tables_figures_and_provenance(pages):
    d, out = pages
    fit = read_campaign_h5(d / "fit.h5")
    p = parse(out["fit"])
    text = out["fit"].read_text(encoding="utf-8")
    assert not re.search(r"(src|href)=\"(?!data:)", text)  # nothing to fetch: every resource is inline
    assert "<script" not in text and "http://" not in text and "https://" not in text
    images = [a for tag, a in p.tags if tag == "img"]
    assert len(images) >= 3 and all(a["src"].startswith("data:image/png;base64,") for a in images)
    assert any(a["alt"] == "fitted_fit.png" for a in images)  # measured against fitted
    for name in fit.names:
        assert name in p.cells
    assert str(fit.records[0].estimate[0])[:4] in text  # the estimate of m is in its table
    assert fit.config.digest() in text and "data_sha256" in text and str(d / "run.csv") in text  # provenance
    assert "adequate: the residual is at the noise" in text  # the verdict of a fit on measured data


def test_table_html_keeps_every_row_and_escapes():
    from rich.table import Table

    t = Table(title="a <b> & c")
    t.add_column("parameter")
    t.add_column("value")
    t.add_row("m", "1.5")
    t.add_row("[bold]Ix[/]", "<2>")
    html = table_html(t)
    assert "<caption>a &lt;b&gt; &amp; c</caption>" in html
    assert html.count("<tr>") == 3 and "<td>Ix</td>" in html and "&lt;2&gt;" in html
    assert '<td class="num">1.5</td>' in html
    assert "<h2>x</h2>" in page("t", [Section(title="x")])


def test_report_html_is_refused_with_a_wrong_suffix(pages, tmp_path):
    d, _ = pages
    res = cli("report", d / "fit.h5", "--html", tmp_path / "page.txt")
    assert res.exit_code == 2, res.output
    assert ".html" in res.stderr and not (tmp_path / "page.txt").exists()


# ------------------------------------------------------------------------------------------ in a real browser


def _browser():
    """A headless chromium through selenium, or skip (fail in CI, where `make test` installs it) with the reason."""
    missing = []
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        missing.append("the selenium package (pip install -e '.[test]')")
    binary = next((shutil.which(b) for b in ("chromium", "chromium-browser") if shutil.which(b)), None)
    driver = shutil.which("chromedriver")
    if binary is None or driver is None:
        missing.append("Debian's chromium and chromium-driver (make test installs them: apt-get install -y chromium "
                       "chromium-driver)")  # fmt: skip
    if missing:
        reason = "no headless browser: " + "; ".join(missing)
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--window-size=1280,900"):  # fmt: skip
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(driver), options=options)


@pytest.fixture(scope="module")
def browser():
    b = _browser()
    yield b
    b.quit()


def test_the_diagnosis_page_has_the_verdict_checks_and_the_channels_before_and_after(pages):
    d, out = pages
    doc = json.loads((d / "diagnose.json").read_text())
    text = out["diagnose"].read_text(encoding="utf-8")
    assert f"verdict: {doc['verdict']}" in text and "before / after" in text
    p = parse(out["diagnose"])
    alts = [a["alt"] for tag, a in p.tags if tag == "img"]
    assert "run-channels.png" in alts and "run-residual.png" in alts
    assert str(d / "run.csv") in text and "data sha256" in text
    assert not re.search(r"(src|href)=\"(?!data:)", text) and "<script" not in text


@pytest.mark.parametrize("stem", ["fit", "sim", "damper", "diagnose"])
def test_the_page_renders_in_a_headless_browser(pages, browser, stem):
    from selenium.webdriver.common.by import By

    d, out = pages
    browser.get(out[stem].resolve().as_uri())
    assert browser.title.startswith("vehid diagnose" if stem == "diagnose" else "vehid report")
    rows = browser.find_elements(By.CSS_SELECTOR, "table tbody tr")
    first = [r.find_element(By.CSS_SELECTOR, "td").text for r in rows]
    for name in names_of(d, stem):  # a row per parameter, its name visible
        row = next(r for r, n in zip(rows, first, strict=True) if n.split()[0] == name)
        assert row.is_displayed() and row.size["height"] > 0
    images = browser.find_elements(By.TAG_NAME, "img")
    assert len(images) >= 2
    for img in images:  # every figure decoded and laid out
        natural = browser.execute_script("return [arguments[0].complete, arguments[0].naturalWidth]", img)
        assert natural[0] and natural[1] > 0, img.get_attribute("alt")
        assert img.size["width"] > 0 and img.size["height"] > 0
    alts = [img.get_attribute("alt") for img in images]
    fitted = any(a.startswith("fitted") or a.endswith("-channels.png") for a in alts)
    assert fitted == (stem != "sim"), alts  # measured data: against the fit
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
