# Every target installs what it needs into .venv first, so each works on a fresh machine.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: demo test test-all lint bench bench-sweep paper close-the-loop design clean browser

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

## demo: the paper's car: simulate its bump run, identify it (10 runs, ABC and hybrid), report with figures
demo: $(STAMP)
	mkdir -p runs/demo
	$(BIN)/vehid simulate configs/gokdag2015/base.yaml -o runs/demo/bump.csv --plot runs/demo/bump.png
	$(BIN)/vehid identify configs/gokdag2015/base.yaml --runs 10 -o runs/demo/abc.h5
	$(BIN)/vehid identify configs/gokdag2015/base.yaml --runs 10 -o runs/demo/hybrid.h5 \
	    --set identify.algorithm.name=hybrid --set identify.objective=wls --set sensors=acc --json runs/demo/hybrid.json
	$(BIN)/vehid report runs/demo --plots runs/demo/figures

## browser: Debian's chromium and chromium-driver, for the browser test of `vehid report --html`: installed with
## apt-get when missing and possible (root or password-less sudo; apt-get update only when the install fails)
APT_BROWSER := env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >/dev/null
browser:
	@if command -v chromedriver >/dev/null 2>&1 && { command -v chromium >/dev/null 2>&1 || \
	        command -v chromium-browser >/dev/null 2>&1; }; then exit 0; fi; \
	if ! command -v apt-get >/dev/null 2>&1; then \
	    echo "note: no apt-get here: install chromium and chromedriver, else the browser test is skipped"; exit 0; fi; \
	if [ "$$(id -u)" = 0 ]; then SUDO=; elif sudo -n true 2>/dev/null; then SUDO="sudo -n"; else \
	    echo "note: not root and no sudo: the browser test is skipped (apt-get install chromium chromium-driver)"; \
	    exit 0; fi; \
	echo "installing chromium and chromium-driver (apt-get) for the browser test"; \
	$$SUDO $(APT_BROWSER) 2>&1 || { $$SUDO apt-get update -q >/dev/null && $$SUDO $(APT_BROWSER); } || \
	    echo "note: chromium could not be installed: the browser test is skipped"

## test: lint and the fast test suite (what CI runs)
test: $(STAMP) browser
	$(BIN)/ruff check vehid_cli tests benchmarks examples
	$(BIN)/python -m compileall -q vehid_cli  # bytecode as an installed package has it: the suite's CLI processes
	$(BIN)/python -m pytest -q -m "not slow" -n 2 --dist loadfile  # would each compile vehid_cli anew where PYTHONDONTWRITEBYTECODE is set

## test-all: the whole suite, long checks included
test-all: $(STAMP) browser
	$(BIN)/python -m compileall -q vehid_cli
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check vehid_cli tests benchmarks examples
	$(BIN)/ruff format --check vehid_cli tests benchmarks examples

## bench: speed benchmarks (not tests); results are recorded in benchmarks/RESULTS.md
bench: $(STAMP)
	NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python benchmarks/bench_simulation.py
	NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python benchmarks/bench_damper.py
	NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python benchmarks/bench_time_to_bound.py
	$(BIN)/python benchmarks/bench_campaign.py --repeats 3
	$(BIN)/python benchmarks/bench_long_record.py --repeats 3
	$(BIN)/python benchmarks/bench_diagnose.py --repeats 3 --long
	$(BIN)/python benchmarks/bench_design.py --repeats 3

## bench-sweep: also time the whole Table 1 + 2 sweep (about 2-4 minutes)
bench-sweep: $(STAMP)
	$(BIN)/python benchmarks/bench_campaign.py --repeats 3 --sweep

## paper: reproduce Gokdag (2015) Tables 1-2 plus our estimators, and regenerate docs/results/gokdag2015.md
PAPER_SWEEP := runs/gokdag2015
CRLB_SWEEP  := runs/gokdag2015-crlb
SEED_SWEEP  := runs/gokdag2015-seeds
paper: $(STAMP)
	$(BIN)/vehid sweep configs/gokdag2015/base.yaml -o $(PAPER_SWEEP) \
	    --vary identify.objective=f1,f2 --vary noise.level=0.1,0.2 --vary identify.algorithm.name=ga,cpso,abc,hybrid
	$(BIN)/vehid sweep configs/gokdag2015/base.yaml -o $(CRLB_SWEEP) \
	    --set identify.objective=wls --set identify.algorithm.name=hybrid --vary sensors=acc,disp --vary noise.level=0.1,0.2
	$(BIN)/vehid sweep configs/gokdag2015/base.yaml -o $(SEED_SWEEP) --runs 100 \
	    --set identify.objective=wls --set identify.algorithm.name=hybrid --vary sensors=acc,disp --vary identify.seed=7,99
	$(BIN)/python docs/results/make_gokdag2015.py $(PAPER_SWEEP) $(CRLB_SWEEP) $(SEED_SWEEP) docs/results/gokdag2015.md

## design: vehid design on the paper's car (with 30-run campaigns checking the bound) -> docs/results/design.md
design: $(STAMP)
	$(BIN)/python docs/results/make_design.py docs/results/design.md

## close-the-loop: vehid diagnose on the bump runs and the two real dampers -> docs/results/close-the-loop.md
close-the-loop: $(STAMP)
	$(BIN)/python docs/results/make_close_the_loop.py docs/results/close-the-loop.md

clean:
	rm -rf $(VENV) runs/demo .pytest_cache

## dampers: identify the measured dampers of configs/dampers/ and regenerate docs/results/dampers.md (about 5 minutes)
.PHONY: dampers
dampers: $(STAMP)
	$(BIN)/python docs/results/make_dampers.py runs/dampers docs/results/dampers.md
