"""Logger files read back as the known run (tests/logger_files.py) in SI units on one grid; bad input is InputError
naming the file and the channel."""

from __future__ import annotations

import os
import signal
import warnings

import numpy as np
import pytest
import scipy.io

from tests.logger_files import CHANNELS, HF_AMPLITUDE, G, csv_times, offset_si, truth, write_csv, write_logger_run
from vehid_cli.core.errors import InputError
from vehid_cli.io.measurement import check_time
from vehid_cli.io.read import read_record
from vehid_cli.io.record import Record, remove_offset

SUFFIX = {"mf4": "mf4", "mat": "mat", "mat73": "mat", "h5": "h5", "csv": "csv"}
SLOW = ("acc_fl", "acc_rr", "disp_fl")  # no content near 150 Hz: comparable on every grid
UNITS = {"acc_fl": "g", "acc_hf": "g", "acc_rr": "g", "disp_fl": "mm"}


def amplitude(ours: str) -> float:
    t = np.linspace(0, 1, 2001)
    y = truth(ours, t, low_pass=True)
    return float(np.ptp(y) / 2)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("logger")
    return {fmt: write_logger_run(d / f"run_{fmt}.{SUFFIX[fmt]}", fmt) for fmt in SUFFIX}


H5_PATHS = {ours: f"{theirs.split('_')[0].lower()}/{theirs}" for ours, theirs in CHANNELS.items()}  # acc/ACC_FL_Z


def read(files, fmt, **kw) -> Record:
    channels = kw.pop("channels", H5_PATHS if fmt == "h5" else CHANNELS)
    units = kw.pop("units", None if fmt in ("mf4", "h5") else {k: UNITS[k] for k in channels})  # those declare units
    return read_record(files[fmt], channels, units, **kw)


@pytest.mark.parametrize("fmt", ["mf4", "mat", "mat73", "h5"])
def test_each_format_gives_the_known_signals_in_si_on_one_1khz_grid(files, fmt):
    rec = read(files, fmt)
    # MDF4: the 200 Hz group ends at 3.995 s, the common span; the others hold 4000 samples at 1 kHz
    n = 3996 if fmt == "mf4" else 4000
    assert rec.t.size == n and rec.rate == pytest.approx(1000.0, rel=1e-12)
    assert check_time(rec.t, "grid") == pytest.approx(1e-3, rel=1e-12) and rec.t[0] == 0.0
    assert set(rec.channels) == set(CHANNELS)
    first = rec.t < 1.0
    for ours in SLOW:
        err = np.max(np.abs(rec.channels[ours] - truth(ours, rec.t)))
        # at 1 kHz in the file: exact; the 200 Hz MDF4 group through a cubic spline: < 1e-3 of the amplitude
        tol = 1e-3 if fmt == "mf4" and ours in ("acc_rr", "disp_fl") else 1e-12
        assert err <= tol * amplitude(ours), (ours, err)
        # the offset as written, in SI: the mean over the first second (whole cycles of 3, 11 and 2 Hz)
        assert np.mean(rec.channels[ours][first]) == pytest.approx(offset_si(ours), abs=tol * amplitude(ours))


def test_a_200hz_channel_on_the_1khz_grid_is_the_sine_a_cubic_spline_gives_not_a_linear_one(files):
    rec = read(files, "mf4", channels={"acc_rr": "ACC_RR_Z"} | {"acc_fl": "ACC_FL_Z"})
    err = np.max(np.abs(rec.channels["acc_rr"] - truth("acc_rr", rec.t)))
    t200 = np.arange(800) / 200
    linear = np.max(np.abs(np.interp(rec.t, t200, truth("acc_rr", t200)) - truth("acc_rr", rec.t)))
    assert err < 1e-3 * amplitude("acc_rr") < linear / 10  # 11 Hz at 200 Hz: linear interpolation errs 1.5 %


def test_down_to_200hz_the_150hz_content_is_filtered_out_not_folded_to_50hz(files):
    rec = read(files, "mf4", channels={"acc_hf": "ACC_HF_Z", "acc_fl": "ACC_FL_Z"}, rate=200.0)
    assert rec.rate == pytest.approx(200.0) and rec.t.size == 800
    inner = (rec.t > 0.2) & (rec.t < rec.t[-1] - 0.2)  # away from the filter's start-up at the record's ends
    residual = rec.channels["acc_hf"] - truth("acc_hf", rec.t, low_pass=True)
    assert np.max(np.abs(residual[inner])) < 0.01 * HF_AMPLITUDE * G  # attenuated to < 1 % (-40 dB)
    # the 4 Hz part passes: its amplitude (least squares) within 0.5 % of the 0.1 g written
    t = rec.t[inner]
    basis = np.column_stack([np.sin(8 * np.pi * t), np.cos(8 * np.pi * t), np.ones_like(t)])
    coef = np.linalg.lstsq(basis, rec.channels["acc_hf"][inner], rcond=None)[0]
    assert np.hypot(*coef[:2]) == pytest.approx(0.1 * G, rel=5e-3)
    # the test can fail: every 5th sample of the 1 kHz channel folds the 150 Hz sine onto 50 Hz at full amplitude
    naive = truth("acc_hf", rec.t) - truth("acc_hf", rec.t, low_pass=True)
    assert np.max(np.abs(naive)) > 0.9 * HF_AMPLITUDE * G
    # slow channels are unaffected by the filter
    assert np.max(np.abs(rec.channels["acc_fl"] - truth("acc_fl", rec.t))[inner]) < 1e-3 * amplitude("acc_fl")


def test_csv_with_iso_stamps_at_a_jittered_300hz_is_resampled_at_the_median_rate(files):
    rec = read(files, "csv", channels={k: CHANNELS[k] for k in SLOW})
    stamps = csv_times()
    assert np.ptp(np.diff(stamps)) > 0.02 / 300  # the file really jitters (by ±2 % of a step at each stamp)
    assert rec.rate == pytest.approx(1 / np.median(np.diff(stamps)), rel=1e-8)
    assert rec.rate == pytest.approx(300.0, rel=0.01)
    assert rec.t.size == int(np.floor(stamps[-1] * rec.rate)) + 1
    for ours in SLOW:
        err = np.max(np.abs(rec.channels[ours] - truth(ours, rec.t)))
        assert err < 1e-4 * amplitude(ours), (ours, err)  # spline of a 2..11 Hz sine at 300 Hz; stamps to 1 µs


def test_the_window_keeps_start_to_stop_of_the_record_time(files):
    rec = read(files, "h5", window=(1.0, 2.5))
    assert rec.t[0] == pytest.approx(1.0) and rec.t[-1] < 2.5 and rec.t.size == 1500
    assert np.max(np.abs(rec.channels["acc_fl"] - truth("acc_fl", rec.t))) < 1e-12


def test_remove_offset_over_the_first_second_and_the_mean(files):
    rec = read(files, "mat")
    still = remove_offset(rec, ["acc_fl", "acc_rr"], mode="first_second")
    for ours in ("acc_fl", "acc_rr"):
        assert np.max(np.abs(still.channels[ours] - (truth(ours, rec.t) - offset_si(ours)))) < 1e-9
    assert np.array_equal(still.channels["disp_fl"], rec.channels["disp_fl"])  # not named: untouched
    mean = remove_offset(rec, ["disp_fl"])
    assert np.mean(mean.channels["disp_fl"]) == pytest.approx(0.0, abs=1e-12)
    assert np.mean(rec.channels["disp_fl"]) == pytest.approx(offset_si("disp_fl"), rel=1e-9)  # 8 whole cycles
    with pytest.raises(InputError, match="acc_xx.*did you mean 'acc_rr'"):
        remove_offset(rec, ["acc_xx"])


def test_a_mat_struct_is_found_without_the_variable_and_by_name(files):
    by_name = read(files, "mat", variable="run")
    found = read(files, "mat")
    assert np.array_equal(by_name.channels["acc_fl"], found.channels["acc_fl"])


def test_mat73_is_read_as_hdf5_behind_the_matlab_header(files):
    with pytest.raises(NotImplementedError):  # the file is what MATLAB's -v7.3 writes, as scipy sees it
        scipy.io.loadmat(files["mat73"])
    assert np.array_equal(read(files, "mat73").channels["acc_fl"], read(files, "mat").channels["acc_fl"])


# ------------------------------------------------------------------------------------------ bad input


def raises(files_or_path, *fragments, **kw) -> str:
    with pytest.raises(InputError) as info:
        if isinstance(files_or_path, tuple):
            read(*files_or_path, **kw)
        else:
            read_record(files_or_path, **kw)
    msg = str(info.value)
    for fragment in fragments:
        assert fragment in msg, (fragment, msg)
    return msg


@pytest.mark.parametrize("fmt", ["mf4", "mat", "mat73", "h5", "csv"])
def test_a_channel_not_in_the_file_is_named_with_the_names_present(files, fmt):
    prefix = "acc/" if fmt == "h5" else ""
    raises(
        (files, fmt),
        str(files[fmt]),
        f"'{prefix}ACC_FL'",
        f"did you mean '{prefix}ACC_FL_Z'",
        "ACC_RR_Z",
        "'acc_fl'",
        channels={"acc_fl": f"{prefix}ACC_FL"},
    )


def test_an_unknown_unit_names_file_channel_and_the_known_units(files):
    raises((files, "mf4"), str(files["mf4"]), "acc_fl", "ACC_FL_Z", "'gee'", "m/s^2", "mm", units={"acc_fl": "gee"})


def test_a_mat_without_the_variable_lists_the_variables(files):
    raises((files, "mat"), str(files["mat"]), "'runs'", "did you mean 'run'", "operator", variable="runs")
    raises((files, "mat73"), str(files["mat73"]), "'runs'", "did you mean 'run'", variable="runs")


def test_non_finite_samples_name_file_and_channel(tmp_path):
    path = tmp_path / "nan.csv"
    path.write_text("t,ACC\n0,1\n0.01,nan\n0.02,1\n0.03,1\n")
    raises(path, str(path), "acc", "'ACC'", "non-finite", "sample 2", channels={"acc": "ACC"})


def test_a_time_that_goes_backwards_names_file_and_channel(tmp_path):
    path = tmp_path / "back.csv"
    t = csv_times()[:50]
    write_csv(path, np.concatenate([t[:20], t[21:22], t[20:21], t[22:]]))
    raises(path, str(path), "acc_fl", "backwards", "sample 22", channels={"acc_fl": "ACC_FL_Z"})


def test_a_gap_in_time_is_not_jitter(tmp_path):
    path = tmp_path / "gap.csv"
    t = csv_times()[:50]
    write_csv(path, np.concatenate([t[:20], t[22:]]))
    raises(path, str(path), "acc_fl", "gap", channels={"acc_fl": "ACC_FL_Z"})


def test_half_a_step_of_jitter_is_read_at_the_grids_rate_and_a_dropped_sample_among_it_is_a_gap(tmp_path):
    """A lab rig's clock: every stamp anywhere within half a step of its slot (steps from near 0 to near 2): read at
    the rate of the grid the stamps were drawn around; one sample dropped mid-way in such stamps, and one dropped
    near the end of clean stamps, are gaps (the slots judge, not the steps alone)."""
    rng = np.random.default_rng(5)
    k = np.arange(1200)
    t = np.round((k + rng.uniform(-0.5, 0.5, k.size) * (k > 0)) / 300.0 * 1e6) / 1e6
    assert np.diff(t).max() > 1.9 / 300 and np.diff(t).min() < 0.1 / 300
    path = tmp_path / "jitter.csv"
    write_csv(path, t)
    record = read_record(path, channels={"acc_fl": "ACC_FL_Z"})
    assert record.rate == pytest.approx(300.0, rel=2e-4)
    write_csv(path, np.delete(t, 600))
    raises(path, str(path), "acc_fl", "gap", channels={"acc_fl": "ACC_FL_Z"})
    clean = np.round(k / 300.0 * 1e6) / 1e6
    write_csv(path, np.delete(clean, k.size - 3))
    raises(path, str(path), "acc_fl", "gap", channels={"acc_fl": "ACC_FL_Z"})


def test_a_window_outside_the_record_names_the_window_and_the_span(files):
    raises((files, "mf4"), str(files["mf4"]), "[10, 20)", "[0, 3.995]", window=(10.0, 20.0))


def test_an_unknown_suffix_and_a_missing_file(tmp_path):
    raises(tmp_path / "run.xlsx", "run.xlsx", ".mf4", channels={"a": "A"})
    raises(tmp_path / "none.mf4", "none.mf4", "not found", channels={"a": "A"})


# ------------------------------------------------------------------------------------------ native samples


def test_rates_and_native_samples_of_a_200hz_channel_on_the_1khz_grid(files):
    rec = read(files, "mf4")
    assert rec.rates == {"acc_fl": 1000.0, "acc_hf": 1000.0, "acc_rr": 200.0, "disp_fl": 200.0}
    assert np.array_equal(rec.native_samples("acc_fl"), np.arange(rec.t.size))
    k = rec.native_samples("acc_rr")
    assert np.array_equal(k, np.arange(0, rec.t.size, 5))  # every 5th grid point: 0, 5 ms, ..., 3.995 s
    t200 = np.arange(800) / 200  # the written 200 Hz stamps
    for ours in ("acc_rr", "disp_fl"):
        # the file's samples, to round-off (between them a spline errs up to 1e-3 of the amplitude)
        assert np.max(np.abs(rec.channels[ours][k] - truth(ours, t200))) < 1e-12 * amplitude(ours)


def test_native_samples_after_a_window_and_an_offset_removal_refer_to_the_windowed_grid(files):
    rec = remove_offset(read(files, "mf4", window=(1.0021, 2.5)), ["acc_rr"])
    assert rec.t[0] == pytest.approx(1.003) and rec.rates["acc_rr"] == 200.0
    k = rec.native_samples("acc_rr")
    assert rec.t[k[0]] == pytest.approx(1.005) and np.all(np.diff(k) == 5)
    assert rec.t[k[-1]] == pytest.approx(2.495)
    t200 = np.arange(201, 500) / 200
    shifted = truth("acc_rr", t200) - np.mean(truth("acc_rr", rec.t))  # the offset removed: the window's mean
    assert np.max(np.abs(rec.channels["acc_rr"][k] - shifted)) < 1e-3 * amplitude("acc_rr")
    assert np.max(np.abs(np.diff(rec.channels["acc_rr"][k]) - np.diff(truth("acc_rr", t200)))) < 1e-12


def test_native_samples_off_the_grid_are_an_error_unless_nearest(files):
    rec = read(files, "mf4", channels={"acc_fl": "ACC_FL_Z", "acc_rr": "ACC_RR_Z"}, rate=300.0)
    assert rec.rates["acc_rr"] == 200.0  # 200 Hz does not divide 300 Hz: every other sample is between grid points
    with pytest.raises(InputError, match=r"acc_rr.*200 Hz.*300 Hz grid.*nearest=True"):
        rec.native_samples("acc_rr")
    k = rec.native_samples("acc_rr", nearest=True)
    t200 = np.arange(800) / 200
    t200 = t200[t200 <= rec.t[-1]]
    assert k.size == t200.size and np.max(np.abs(rec.t[k] - t200)) <= 0.5 / 300 + 1e-12


# ------------------------------------------------------------------------------------------ resample=False


def test_without_resampling_different_rates_are_an_error_naming_each_channel_and_rate(files):
    msg = raises(
        (files, "mf4"), str(files["mf4"]), "'acc_fl' ('ACC_FL_Z') 1000 Hz", "'acc_rr' ('ACC_RR_Z') 200 Hz",
        "data.resample", channels={"acc_fl": "ACC_FL_Z", "acc_rr": "ACC_RR_Z"}, resample=False,
    )  # fmt: skip
    assert "resampl" in msg
    raises((files, "mf4"), "grid rate 500 Hz", channels={"acc_fl": "ACC_FL_Z"}, rate=500.0, resample=False)
    # one rate: read as the file's samples, exactly
    rec = read(files, "mf4", channels={"acc_fl": "ACC_FL_Z", "acc_hf": "ACC_HF_Z"}, resample=False)
    assert rec.t.size == 4000 and np.max(np.abs(rec.channels["acc_fl"] - truth("acc_fl", rec.t))) < 1e-15


def test_without_resampling_jittered_stamps_are_an_error(files):
    raises((files, "csv"), str(files["csv"]), "acc_fl", "jitter", "resample=True", channels={"acc_fl": "ACC_FL_Z"},
           resample=False)  # fmt: skip


def test_without_resampling_a_channel_between_the_grid_points_is_an_error(tmp_path):
    path = tmp_path / "phase.mat"
    t = np.arange(100) / 100
    scipy.io.savemat(path, {"t": t, "A": np.sin(t), "B": np.cos(t), "t_B": t + 0.004})  # B 4 ms after A
    # the grid starts at the latest first sample, B's: A's samples fall 4 ms after grid points
    raises(path, str(path), "'a' ('A')", "not on the common grid", channels={"a": "A", "b": "B"}, resample=False)
    rec = read_record(path, {"a": "A", "b": "B"})  # resampled: A's spline at B's stamps
    assert rec.t.size == 99 and rec.rates == {"a": 100.0, "b": 100.0}
    assert np.array_equal(rec.channels["b"], np.cos(t[:99]))  # B's own samples, on the grid
    assert np.max(np.abs(rec.channels["a"] - np.sin(rec.t + 0.004))) < 1e-6


def test_the_bench_reader_passes_resample_false_on(tmp_path):
    from vehid_cli.systems.damper.bench import read_bench

    path = tmp_path / "bench.csv"
    t = csv_times()[:50]  # jittered stamps
    path.write_text("t,x,F\n" + "".join(f"{float(s)!r},{float(np.sin(s))!r},1.0\n" for s in t))
    columns = {"time": "t", "displacement": "x", "force": "F"}
    assert read_bench(path, columns, {}).t.size > 3  # resampled by default
    with pytest.raises(InputError, match="jitter.*data.resample"):
        read_bench(path, columns, {}, resample=False)


# ------------------------------------------------------------------------------------------ damaged files (issue 22)


def _damaged(files, fmt, tmp_path, edit):
    data = bytearray(files[fmt].read_bytes())
    edit(data)
    path = tmp_path / files[fmt].name
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("fmt, what", [("mf4", "ASAM MDF"), ("h5", "HDF5"), ("mat73", "HDF5 (MATLAB v7.3)")])
def test_a_truncated_binary_file_is_damaged_naming_the_file_and_printing_nothing(files, tmp_path, capfd, fmt, what):
    path = _damaged(files, fmt, tmp_path, lambda d: d.__delitem__(slice(len(d) // 3, None)))
    channels = H5_PATHS if fmt == "h5" else CHANNELS
    raises(path, str(path), f"cannot read as {what}", "damaged", channels=channels)
    captured = capfd.readouterr()  # asammdf's MDF4.__del__ traceback and HDF5's error stack stay in the child
    assert "Traceback" not in captured.err + captured.out and "Exception ignored" not in captured.err


def test_an_mdf4_channel_group_declaring_2_34_samples_is_refused_before_it_is_read(files, tmp_path):
    from asammdf import MDF

    with MDF(files["mf4"]) as mdf:
        cycles = mdf.groups[0].channel_group.cycles_nr
    needle = int(cycles).to_bytes(8, "little")

    def inflate(data):
        at = data.find(b"##CG")
        at = data.find(needle, at)  # cg_cycle_count, the first 8-byte field after the links
        data[at : at + 8] = (2**34).to_bytes(8, "little")

    path = _damaged(files, "mf4", tmp_path, inflate)
    raises(path, str(path), "channel group 0 declares 17179869184 samples", "GiB", "bytes can hold", channels=CHANNELS)


def _segfault(src):
    """A MAT reader that crashes (module level: the reader's child is a fresh interpreter, core/isolated.py)."""
    os.kill(os.getpid(), signal.SIGSEGV)


def test_a_mat_reader_that_crashes_is_exit_2_not_a_dead_process(files, monkeypatch):
    from vehid_cli.io.formats import mat

    monkeypatch.setattr(mat, "_load_v5", _segfault)
    raises((files, "mat"), str(files["mat"]), "cannot read as a MATLAB file", "the reader crashed (SIGSEGV")


def test_a_damaged_compressed_mat_v5_is_damaged_not_a_zlib_error(tmp_path):
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, {"t": np.arange(500) / 100.0, "ACC": np.sin(np.arange(500))}, do_compression=True)
    data = bytearray(path.read_bytes())
    data[200:210] = bytes(10)
    path.write_bytes(bytes(data))
    raises(path, str(path), "cannot read as a MATLAB file", channels={"acc": "ACC"})


def _h5_unit(path, value):
    import h5py

    with h5py.File(path, "w") as f:
        f.create_dataset("t", data=np.arange(100) / 100.0)
        f.create_dataset("acc", data=np.zeros(100)).attrs["unit"] = value


def test_an_hdf5_unit_attribute_that_is_not_utf8_text_names_the_dataset(tmp_path):
    path = tmp_path / "run.h5"
    _h5_unit(path, np.bytes_(b"\xff\xfe m/s"))
    raises(path, str(path), "dataset 'acc'", "not UTF-8 text", channels={"acc": "acc"})
    _h5_unit(path, np.array([1.0, 2.0]))
    raises(path, str(path), "dataset 'acc'", "not text (a float64 array of shape (2,))", channels={"acc": "acc"})
    _h5_unit(path, "mm" * 50_000)
    msg = raises(path, str(path), "'acc'", "100000 characters long", channels={"acc": "acc"})
    assert len(msg) < 400


def test_an_hdf5_dataset_name_that_is_not_utf8_is_listed_escaped(tmp_path):
    """A flipped byte in a dataset's name (the fuzz campaign's hdf5data-00118): h5py gives the name as bytes; the
    channel it was is missing, and the names present are listed with the byte escaped (it had been an internal
    error joining bytes into the message)."""
    import h5py

    path = tmp_path / "run.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("t", data=np.arange(100) / 100.0)
        f.create_dataset(b"ACC\xffRR", data=np.zeros(100))
    raises(path, str(path), "dataset 'ACC_RR' is not in the file", "ACC\\xffRR", channels={"acc": "ACC_RR"})


def test_a_damaged_hdf5_chunk_is_damaged_naming_the_file(tmp_path):
    import h5py

    path = tmp_path / "run.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("t", data=np.arange(4000) / 100.0)
        f.create_dataset("acc", data=np.sin(np.arange(4000.0)), chunks=(500,), compression="gzip", fletcher32=True)
    data = bytearray(path.read_bytes())
    data[-3000:-2990] = bytes(10)
    path.write_bytes(bytes(data))
    raises(path, str(path), "cannot read as HDF5", "damaged", channels={"acc": "acc"})


def test_a_sample_beyond_1e12_is_no_measurement(tmp_path):
    path = tmp_path / "huge.csv"
    path.write_text("t,ACC\n" + "".join(f"{k / 100},{1e300 if k == 7 else 0.5}\n" for k in range(50)))
    raises(path, str(path), "'acc' ('ACC')", "beyond ±1e+12", "sample 8", "1e+300", channels={"acc": "ACC"})


# ------------------------------------------------------------------------------------------ the grid's size


@pytest.mark.parametrize("rate", [1e9, 1e12, 1e300])
def test_a_grid_rate_far_above_the_channels_is_refused_before_it_is_allocated(files, rate):
    raises((files, "mf4"), "at most 100 times", "1000 Hz", f"{rate:g} Hz", rate=rate)


def test_a_grid_beyond_the_memory_budget_is_refused_with_the_numbers(tmp_path, monkeypatch):
    from vehid_cli.io import timegrid

    monkeypatch.setattr(timegrid, "GRID_BUDGET", 1 << 20)
    path = tmp_path / "long.csv"
    path.write_text("t,ACC\n" + "".join(f"{k / 1000},{np.sin(k)}\n" for k in range(40_000)))
    msg = raises(path, str(path), "39.999 s is 40000 samples", "GiB)", channels={"acc": "ACC"})
    assert "the grid at most 0.000976562 GiB" in msg


def test_a_channel_too_short_for_the_anti_alias_filter_is_named(tmp_path):
    path = tmp_path / "short.csv"
    path.write_text("t,ACC\n" + "".join(f"{k / 1000},{np.sin(k)}\n" for k in range(20)))
    raises(path, str(path), "'acc' ('ACC')", "20 samples at 1000 Hz", "too few to low-pass", channels={"acc": "ACC"},
           rate=200.0)  # fmt: skip


def test_a_sample_that_overflows_in_si_is_refused_without_a_numpy_warning(tmp_path):
    path = tmp_path / "overflow.csv"
    path.write_text("t,ACC\n" + "".join(f"{k / 100},{1e308 if k == 7 else 0.5}\n" for k in range(50)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's RuntimeWarning 'overflow encountered in multiply' was printed
        raises(path, str(path), "'acc' ('ACC')", "non-finite", "sample 8", channels={"acc": "ACC"}, units={"acc": "g"})


def _spied_reader(monkeypatch) -> list:
    """The `names` of each MDF4 read in a child (None: every channel, a read ahead), recorded in order."""
    from vehid_cli.io.formats import mdf4

    calls, real = [], mdf4.in_child
    monkeypatch.setattr(
        mdf4, "in_child", lambda fn, src, names, *a, **kw: calls.append(names) or real(fn, src, names, *a, **kw)
    )
    return calls


def test_an_mdf4_file_read_ahead_serves_its_first_read_with_the_same_record(files, monkeypatch):
    from vehid_cli.io.formats import mdf4
    from vehid_cli.io.read import read_ahead

    monkeypatch.setattr(mdf4, "AHEAD_MIN_FILE", 0)  # the test file is small
    one = {"acc_rr": "ACC_RR_Z"}
    before, before_one = read(files, "mf4"), read(files, "mf4", channels=one)
    missing = raises((files, "mf4"), "NOPE", channels={"x": "NOPE"})
    calls = _spied_reader(monkeypatch)
    with read_ahead([files["mf4"], files["csv"]]):
        assert calls == [None]  # every channel of the MDF4 file, in one child; the CSV is read where it is used
        inside = read(files, "mf4")
        assert calls == [None]
        inside_one = read(files, "mf4", channels=one)  # served once: read again, as outside the block
        assert calls == [None, ["ACC_RR_Z"]]
    with read_ahead([files["mf4"]]):
        assert raises((files, "mf4"), channels={"x": "NOPE"}) == missing
    read(files, "mf4", channels=one)
    assert calls == [None, ["ACC_RR_Z"], None, ["ACC_RR_Z"]]
    with read_ahead([files["mf4"]]):
        pass
    read(files, "mf4", channels=one)
    assert calls == [None, ["ACC_RR_Z"], None, ["ACC_RR_Z"], None, ["ACC_RR_Z"]]  # the block's end forgot the file
    for a, b in ((before, inside), (before_one, inside_one)):
        assert np.array_equal(a.t, b.t) and a.rates == b.rates and a.declared == b.declared
        assert a.channels.keys() == b.channels.keys()
        for name in a.channels:
            assert np.array_equal(a.channels[name], b.channels[name], equal_nan=True)
            assert np.array_equal(a.stamps[name], b.stamps[name])


def test_a_small_large_or_damaged_mdf4_file_is_left_to_the_reader(files, tmp_path, monkeypatch):
    from vehid_cli.io.formats import mdf4
    from vehid_cli.io.read import read_ahead

    assert files["mf4"].stat().st_size < mdf4.AHEAD_MIN_FILE
    calls = _spied_reader(monkeypatch)
    with read_ahead([files["mf4"]]):
        assert calls == []  # small: its reader holds little beside its interpreter
    monkeypatch.setattr(mdf4, "AHEAD_MIN_FILE", 0)
    monkeypatch.setattr(mdf4, "AHEAD_BYTES", 1000)  # the file's records are larger
    with read_ahead([files["mf4"]]):
        read(files, "mf4", channels={"acc_rr": "ACC_RR_Z"})
        assert calls == [None, ["ACC_RR_Z"]]  # tried whole, refused by its size: read where it is used
    path = _damaged(files, "mf4", tmp_path, lambda d: d.__delitem__(slice(len(d) // 3, None)))
    with read_ahead([path, tmp_path / "none.mf4"]):  # a damaged file, a missing one: nothing raised here
        raises(path, str(path), "cannot read as ASAM MDF", "damaged", channels=CHANNELS)


def test_the_commands_read_their_logger_files_before_the_compiled_kernels_are_imported(files, tmp_path):
    """`vehid identify`, `diagnose` and `check` read an MDF4 file ahead (named by --data or by the config's
    data.files) while numba is not imported, and serve the file's read from it: the reader child's memory and numba's
    LLVM library one after the other (io.read.read_ahead)."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    base = root / "configs" / "gokdag2015" / "base.yaml"
    code = """
import runpy, sys
from vehid_cli.io.formats import mdf4
mdf4.AHEAD_MIN_FILE = 0  # the test file is small
real, subset = mdf4.Mdf4.read_ahead, mdf4._subset
def spy(self, path):
    print("read ahead", path.name, "numba imported:", "numba" in sys.modules)
    return real(self, path)
def served(*args):
    print("served from the read ahead")
    return subset(*args)
mdf4.Mdf4.read_ahead, mdf4._subset = spy, served
sys.argv = ["vehid", *sys.argv[1:]]
runpy.run_module("vehid_cli", run_name="__main__")
"""
    name = files["mf4"]
    for command in (
        ["identify", str(base), "-o", str(tmp_path / "r.h5")],
        ["diagnose", str(base)],
        ["check", str(base)],
    ):
        for data in (["--data", str(name)], ["--set", f"data.files=[{name}]"]):
            proc = subprocess.run([sys.executable, "-c", code, *command, *data], cwd=root, capture_output=True,
                                  text=True, env=dict(os.environ, PYTHONPATH=str(root)))  # fmt: skip
            # the paper's channels are not in this file: refused after the read
            assert proc.returncode == 2, proc.stderr
            expected = [f"read ahead {name.name} numba imported: False", "served from the read ahead"]
            assert proc.stdout.splitlines()[:2] == expected, (command, data, proc.stdout)
            assert "channel 'acc1' is not in the file" in proc.stderr, proc.stderr


def test_a_file_changed_after_its_read_ahead_is_read_again_and_a_bad_path_raises_nothing(files, tmp_path, monkeypatch):
    from vehid_cli.io.formats import mdf4
    from vehid_cli.io.read import read_ahead

    monkeypatch.setattr(mdf4, "AHEAD_MIN_FILE", 0)
    path = tmp_path / files["mf4"].name
    path.write_bytes(files["mf4"].read_bytes())
    one = {"acc_rr": "ACC_RR_Z"}
    calls = _spied_reader(monkeypatch)
    with read_ahead([path, tmp_path / "a\0b.mf4"]):  # a NUL byte: no file can have that name
        write_logger_run(path, "mf4")  # rewritten (the same values: only the file's identity tells)
        stat = path.stat()
        os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
        read_record(path, one)
        assert calls == [None, ["ACC_RR_Z"]]  # not served from what was read before the change
        read_record(path, one)
        assert calls == [None, ["ACC_RR_Z"], ["ACC_RR_Z"]]
