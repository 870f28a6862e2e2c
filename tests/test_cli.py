"""`vehid simulate` end to end, as a user runs it: real processes, exit codes, files on disk."""

from __future__ import annotations

import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from tests.conftest import BASE_CONFIG, ROOT, VEHICLE_DATA, cli, needs_shared, read_png, vehid
from vehid_cli.io.measurement import read_measurement


def test_simulate_csv_and_plot(tmp_path):
    out, fig = tmp_path / "run.csv", tmp_path / "run.png"
    res = vehid("simulate", BASE_CONFIG, "-o", out, "--plot", fig)
    assert res.returncode == 0, res.stderr
    m = read_measurement(out)
    assert m.t.size == 3000 and m.acc is not None and m.disp is not None
    read_png(fig)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.png"]


def test_simulate_h5_holds_clean_and_noisy(tmp_path):
    out = tmp_path / "run.h5"
    res = vehid("simulate", BASE_CONFIG, "-o", out, "--seed", 11)
    assert res.returncode == 0, res.stderr
    with h5py.File(out) as h5:
        clean, noisy = h5["clean/acc"][()], h5["noisy/acc"][()]
        assert "vehicle:" in h5.attrs["config_yaml"] and h5.attrs["seed"] == 11
        assert h5["clean/q"].shape == (3000, 7)
    ratio = (noisy - clean).std(axis=0) / (0.1 * clean.std(axis=0))
    np.testing.assert_allclose(ratio, 1.0, atol=0.06)


def test_same_seed_same_file_different_seed_different_noise(tmp_path):
    paths = [tmp_path / f"{i}.csv" for i in range(3)]
    for path, seed in zip(paths, (1, 1, 2), strict=True):
        assert vehid("simulate", BASE_CONFIG, "-o", path, "--seed", seed).returncode == 0
    a, b, c = (read_measurement(p).acc for p in paths)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("run", ["bump_run_linear.csv", "bump_run_B.csv"])
def test_road_file_reproduces_the_independent_simulator(tmp_path, run):
    """Acceptance 3. bump_run_linear was made by an independent simulator of the linear car with 5 % noise:
    our clean response to its road must leave exactly that noise. bump_run_B (another road and speed) holds an
    effect the linear model lacks, so there we only check the road and grid are taken from the file."""
    data = needs_shared(VEHICLE_DATA / run)
    out = tmp_path / "sim.csv"
    res = vehid("simulate", BASE_CONFIG, "--road", data, "-o", out, "--set", "noise.level=0")
    assert res.returncode == 0, res.stderr
    sim, meas = read_measurement(out), read_measurement(data)
    np.testing.assert_array_equal(sim.road, meas.road)
    np.testing.assert_allclose(sim.t, meas.t, atol=1e-12)
    if run == "bump_run_linear.csv":
        for family in ("acc", "disp"):
            residual = getattr(meas, family) - getattr(sim, family)
            expected = 0.05 * getattr(sim, family).std(axis=0)
            np.testing.assert_allclose(residual.std(axis=0) / expected, 1.0, atol=0.05)
            assert np.abs(residual.mean(axis=0) / expected).max() < 0.1


def test_newmark_and_exact_agree_from_the_cli(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert vehid("simulate", BASE_CONFIG, "-o", a, "--set", "noise.level=0").returncode == 0
    assert (
        vehid(
            "simulate", BASE_CONFIG, "-o", b, "--set", "noise.level=0", "--set", "simulation.integrator=newmark"
        ).returncode
        == 0
    )
    acc_a, acc_b = read_measurement(a).acc, read_measurement(b).acc
    assert np.sqrt(np.mean((acc_a - acc_b) ** 2) / np.mean(acc_a**2)) < 1e-3


def bad_road(tmp_path):
    path = tmp_path / "road_missing_column.csv"
    path.write_text("t,road1,road2,road4\n0,0,0,0\n0.001,0,0,0\n0.002,0,0,0\n")
    return path


def uneven_road(tmp_path):
    path = tmp_path / "road_uneven.csv"
    path.write_text("t,road1,road2,road3,road4\n0,0,0,0,0\n0.001,0,0,0,0\n0.0025,0,0,0,0\n0.0035,0,0,0,0\n")
    return path


BAD_INPUTS = {
    "unknown key": (["--set", "vehicle.mas=1300"], ["'vehicle.mas'", "did you mean 'm'"]),
    "wrong type": (["--set", "road.speed_kmh=fast"], ["'road.speed_kmh'", "fast"]),
    "negative mass": (["--set", "vehicle.m=-1300"], ["'vehicle.m'", "must be in [0.1, 1e+06]"]),
    "a1 outside wheelbase": (["--set", "vehicle.a2=null", "--set", "vehicle.wheelbase=2.6", "--set", "vehicle.a1=2.7"],
                             ["'vehicle.a1'", "outside the wheelbase"]),
    "dt too coarse": (["--set", "simulation.dt=0.01"], ["'simulation.dt'", "wheel-hop"]),
    "unknown output type": (["-o", "{tmp}/out.txt"], ["out.txt", ".csv"]),
    "missing output dir": (["-o", "{tmp}/nodir/out.csv"], ["does not exist"]),
    "missing road columns": (["--road", "{bad_road}"], ["road3"]),
    "non-uniform time": (["--road", "{uneven_road}"], ["column 't'", "not uniformly sampled"]),
    "unreadable road file": (["--road", "{tmp}/missing.csv"], ["missing.csv", "file not found"]),
    "malformed --set": (["--set", "vehicle.m"], ["dotted.key=value"]),
}  # fmt: skip


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_exits_2_with_one_clear_message(tmp_path, case):
    args, fragments = BAD_INPUTS[case]
    fill = {"tmp": tmp_path, "bad_road": bad_road(tmp_path), "uneven_road": uneven_road(tmp_path)}
    args = [a.format(**fill) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "out.csv")]
    before = set(tmp_path.rglob("*"))
    res = vehid("simulate", BASE_CONFIG, *args)
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert "Traceback" not in res.stderr
    for fragment in fragments:
        assert fragment in res.stderr, res.stderr
    assert set(tmp_path.rglob("*")) == before  # nothing written, nothing half-written


def test_missing_config_file(tmp_path):
    res = vehid("simulate", tmp_path / "nope.yaml", "-o", tmp_path / "o.csv")
    assert res.returncode == 2 and "nope.yaml" in res.stderr and "not found" in res.stderr
    assert "Traceback" not in res.stderr


# ------------------------------------------------------------------------------------------ start-up and help


def test_importing_the_cli_loads_no_heavy_library():
    """`vehid --help` starts in a fraction of a second: the library (NumPy, pydantic, h5py, SciPy, Numba) is
    imported inside the commands, not by `import vehid_cli.cli.app` (which `python -m vehid_cli` does first)."""
    code = (
        "import vehid_cli.cli.app, vehid_cli.__main__, sys; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy','pydantic','h5py','scipy','numba')))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


@pytest.mark.parametrize("command", ["", "simulate", "identify", "sweep", "report", "diagnose"])
def test_dash_h_is_help_and_help_shows_values_not_types(command):
    res = cli(*([command] if command else []), "-h")
    assert res.exit_code == 0, res.output
    assert "Usage: vehid" in res.stdout and "-h, --help" in res.stdout
    for typer_type in ("<str>", "<int>", "<path>", "<list", "<bool>"):
        assert typer_type not in res.stdout, res.stdout
    if command:
        assert "--set KEY=VALUE" in res.stdout and "CONFIG" in res.stdout or command == "report"


def test_help_names_the_allowed_values():
    identify = cli("identify", "--help").stdout
    assert "--executor local|dask" in identify and "--runs N" in identify and "-o, --output FILE" in identify
    sweep = cli("sweep", "--help").stdout
    assert "--vary KEY=V1,V2" in sweep and "--shard K/N" in sweep and "-o, --output DIR" in sweep
    report = cli("report", "--help").stdout
    assert "--format table|md|csv|latex|json" in report and "--plots DIR" in report
    assert "--plots DIR" in cli("diagnose", "--help").stdout and "--road FILE" in cli("simulate", "-h").stdout


# ------------------------------------------------------------------------------------------ errors name options


@pytest.mark.parametrize(
    "args, expected",
    [
        (["--runs", "0"], "error: --runs: 'identify.runs': must be in [1, 100000], got 0"),
        (["--seed", "-1"], "error: --seed: 'identify.seed': must be in [0, 9223372036854775807], got -1"),
        (["--set", "noise.levle=0.1"],
         "error: --set noise.levle=0.1: 'noise.levle': unknown key; did you mean 'level'?"),
        (["--set", "noise.level=0.1", "--set", "identify.algorithm.name=gaa"],
         "error: --set identify.algorithm.name=gaa: 'identify.algorithm.name': unknown algorithm 'gaa'"),
    ],
)  # fmt: skip
def test_an_override_error_names_the_option_not_the_config_file(tmp_path, args, expected):
    res = cli("identify", BASE_CONFIG, *args, "-o", tmp_path / "c.h5")
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith(expected), res.stderr
    assert str(BASE_CONFIG) not in res.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_broken_config_file_is_still_blamed_on_the_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BASE_CONFIG.read_text().replace("  level: 0.10", "  levle: 0.10"))
    res = cli("identify", bad, "--runs", "2", "--set", "noise.level=0.1", "-o", tmp_path / "c.h5")
    assert res.exit_code == 2
    assert res.stderr.startswith(f"error: {bad}: 'noise.levle': unknown key"), res.stderr


def test_an_override_error_names_the_vary_value(tmp_path):
    res = cli("sweep", BASE_CONFIG, "--vary", "noise.level=0.1,abc", "-o", tmp_path / "s")
    assert res.exit_code == 2
    assert res.stderr.startswith("error: --vary noise.level=abc: 'noise.level':"), res.stderr
    assert not (tmp_path / "s").exists()


# ------------------------------------------------------------------------------------------ progress, no terminal

TINY = [
    "simulation.duration=1.5", "simulation.dt=0.002", "identify.algorithm.name=de",
    "identify.algorithm.population=6", "identify.algorithm.iterations=3",
]  # fmt: skip


def test_without_a_terminal_identify_and_sweep_print_a_line_per_finished_step(tmp_path):
    sets = [x for s in TINY for x in ("--set", s)]
    res = cli("identify", BASE_CONFIG, *sets, "--runs", "3", "--jobs", "1", "-o", tmp_path / "c.h5")
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("identify de/f2: run ")]
    assert [ln.split(" done")[0] for ln in lines] == [f"identify de/f2: run {i}/3" for i in (1, 2, 3)], res.stderr
    assert all(ln.endswith((" s elapsed)", " s left)")) for ln in lines) and lines[-1].endswith(" s elapsed)")
    assert "run 3/3" not in res.stdout  # progress goes to stderr, results to stdout
    res = cli(
        "sweep", BASE_CONFIG, *sets, "--runs", "2", "--jobs", "1", "--vary", "noise.level=0.1,0.2", "-o", tmp_path
    )
    assert res.exit_code == 0, res.output
    lines = [ln.split(" done")[0] for ln in res.stderr.splitlines() if ln.startswith("sweep ")]
    assert lines == ["sweep level-0.1: campaign 1/2", "sweep level-0.2: campaign 2/2"], res.stderr


def test_plain_progress_counts_updates_and_advances():
    from vehid_cli.core.progress import PlainProgress

    lines: list[str] = []
    with PlainProgress("identify", "run", lines.append) as progress:
        bar = progress.add_task("abc/f1", total=4)
        progress.update(bar, completed=2)  # two runs finished together: two lines
        progress.update(bar, description="abc/f2")
        progress.advance(bar)
    assert [ln.split(" (")[0] for ln in lines] == [
        "identify abc/f1: run 1/4 done", "identify abc/f1: run 2/4 done", "identify abc/f2: run 3/4 done"
    ]  # fmt: skip


# ------------------------------------------------------------------------------------------ output targets


def read_only_dir(tmp_path):
    """A directory this user cannot write in (None as root, where chmod does not restrict)."""
    if os.geteuid() == 0:
        return None
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    return d


def blocked_targets(tmp_path):
    """Paths no user can make a directory at: under a regular file; and inside a read-only directory."""
    (tmp_path / "somefile").write_text("x")
    targets = [tmp_path / "somefile" / "sub"]
    ro = read_only_dir(tmp_path)
    return targets + ([ro / "sub"] if ro else [])


def test_sweep_and_diagnose_check_their_directories_before_any_work(tmp_path):
    for target in blocked_targets(tmp_path):
        res = cli("sweep", BASE_CONFIG, "--vary", "noise.level=0.1,0.2", "-o", target)
        assert res.exit_code == 2, res.output
        assert res.stderr.startswith(f"error: -o {target}: cannot "), res.stderr
        data = tmp_path / "data.csv"
        data.write_text("t,road1\n")  # never read: the check comes first
        res = cli("diagnose", BASE_CONFIG, "--data", data, "--plots", target)
        assert res.exit_code == 2, res.output
        assert res.stderr.startswith(f"error: --plots {target}: cannot "), res.stderr
        assert "internal error" not in res.output


def test_identify_default_output_directory_is_checked(tmp_path):
    (tmp_path / "runs").write_text("a file where the default output directory goes")
    res = cli("identify", BASE_CONFIG, "--runs", "1", cwd=tmp_path)
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith("error: the default output directory runs: is a file, expected a directory")
    ro = read_only_dir(tmp_path)
    if ro is not None:
        res = cli("identify", BASE_CONFIG, "--runs", "1", cwd=ro)
        assert res.exit_code == 2, res.output
        assert "the default output directory runs" in res.stderr and "Permission denied" in res.stderr


def test_identify_default_output_names_the_data_file_so_campaigns_never_clash(tmp_path):
    """Issue 23 (README "Effects"): `identify CONFIG` then `identify CONFIG --data RUN.csv` in one directory: the
    second default name holds the data file's stem and differs from the first, so it is not refused (exit 2) as
    another campaign's file; the same data file again resumes into the same name."""
    damper = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
    small = ["--set", "identify.budget=60", "--runs", "1", "--jobs", "1"]
    assert cli("simulate", damper, "-o", tmp_path / "bench.csv", cwd=tmp_path).exit_code == 0
    first = cli("identify", damper, *small, cwd=tmp_path)
    assert first.exit_code == 0, first.output
    for _ in range(2):
        res = cli("identify", damper, "--data", "bench.csv", *small, cwd=tmp_path)
        assert res.exit_code == 0, res.output
    names = sorted(p.name for p in (tmp_path / "runs").glob("*.h5"))
    assert len(names) == 2, names
    assert names[0].startswith("synthetic_bingham-bench-") and not names[1].startswith("synthetic_bingham-bench")


# ------------------------------------------------------------------------------------------ hostile options (issue 22)


@pytest.mark.parametrize(
    "name, expected",
    [
        ("o" * 256 + ".csv", "a name of 260 bytes in the output; at most 235 bytes (255 per name, less 20"),
        ("o" * 240 + ".csv", "a name of 244 bytes in the output; at most 235 bytes"),  # its temporary would not fit
        ("€" * 90 + ".csv", "a name of 274 bytes"),
        ("/".join(["d" * 250] * 20) + "/x.csv", "the file system takes at most 4095 for the output"),
    ],
)
def test_an_output_name_the_file_system_cannot_take_exits_2(tmp_path, name, expected, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = cli("simulate", BASE_CONFIG, "-o", name)
    assert res.exit_code == 2 and expected in res.stderr, res.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_seed_outside_64_bits_is_refused_before_any_run(tmp_path):
    for args in (["identify", BASE_CONFIG, "--seed", str(2**64)], ["simulate", BASE_CONFIG, "--seed", str(2**63)]):
        res = cli(*args, "-o", tmp_path / ("c.h5" if args[0] == "identify" else "c.csv"))
        assert res.exit_code == 2 and "must be in [0, 9223372036854775807]" in res.stderr, res.stderr
    assert list(tmp_path.iterdir()) == []  # no .partial: nothing ran


@pytest.mark.parametrize(
    "args, expected",
    [
        (["identify", BASE_CONFIG, "--runs", str(2**63)], "'identify.runs': must be in [1, 100000]"),
        (["identify", BASE_CONFIG, "--jobs", str(2**31)], "--jobs must be in [1, 1024]"),
        (["design", BASE_CONFIG, "--verify", str(10**9)], "--verify must be a number of runs in [0, 100000]"),
        (["sweep", BASE_CONFIG, "--vary", "noise.level=0.1", "--shard", "1/" + "9" * 5000], "--shard expects K/N"),
    ],
)
def test_counts_out_of_range_exit_2_before_any_work(tmp_path, args, expected):
    res = cli(*args, "-o", tmp_path / ("s" if args[0] == "sweep" else "c.h5" if args[0] == "identify" else "d.yaml"))
    assert res.exit_code == 2 and expected in res.stderr, res.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_sweep_of_a_long_value_names_its_file_within_the_limit(tmp_path):
    from vehid_cli.campaign.sweep import parse_vary, plan_sweep

    value = "0." + "1" * 300
    (planned,) = plan_sweep(BASE_CONFIG, [], parse_vary([f"noise.level={value}"]), tmp_path)
    assert len(planned.path.name) < 100 and planned.path.name.startswith("level-0.111")


def test_identify_spawns_its_processes_before_the_compiled_kernels_are_imported(tmp_path):
    """`vehid identify` spawns git (the results' provenance) and `uname -p` (h5py's import asks for the processor)
    while the process is small: numba not imported. Spawned later (vfork), they showed the 200 MiB parent's pages a
    second time in the process tree's summed RSS until they exec'd (the 60 s record's peak read 359-396 MiB in one
    run of three or twelve)."""
    code = """
import runpy, subprocess, sys
real = subprocess.run
def spy(args, *a, **k):
    print(*args[:1], *args[3:4], "numba imported:", "numba" in sys.modules)
    return real(args, *a, **k)
subprocess.run = spy
sys.argv = ["vehid", *sys.argv[1:]]
runpy.run_module("vehid_cli", run_name="__main__")
"""
    args = ["identify", str(BASE_CONFIG), "--runs", "1", "-o", str(tmp_path / "r.h5"), "--set", "simulation.duration=1"]
    proc = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    spawned = [line for line in proc.stdout.splitlines() if "numba imported" in line]
    assert spawned == ["git rev-parse numba imported: False", "git status numba imported: False",
                       "uname numba imported: False"], proc.stdout  # fmt: skip
