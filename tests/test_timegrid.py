"""The grid's own cubic spline (io/timegrid.cubic_spline) against SciPy's CubicSpline and against the cubics it must
reproduce exactly; reading a record whose slower channels are up-sampled leaves scipy.interpolate unloaded."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from tests.logger_files import CHANNELS, write_logger_run
from vehid_cli.io.timegrid import cubic_spline

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("n", [2, 3, 4, 5, 7, 50, 2001])
def test_the_spline_is_scipys_not_a_knot_spline_inside_and_beyond_the_knots(n):
    rng = np.random.default_rng(n)
    for _ in range(5):
        t = np.cumsum(rng.uniform(0.1, 2.0, n))  # uneven steps
        y = rng.standard_normal(n) * 10.0 ** rng.uniform(-3, 3)
        at = np.concatenate([rng.uniform(t[0] - 1, t[-1] + 1, 300), t, [t[0], t[-1]]])
        np.testing.assert_allclose(cubic_spline(t, y, at), CubicSpline(t, y)(at), rtol=1e-12, atol=1e-12 * np.ptp(y))


def test_a_cubic_is_reproduced_and_a_parabola_through_three_points():
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(-2, 3, 40))
    at = np.linspace(-3, 4, 501)

    def cubic(x):
        return 0.5 - 1.5 * x + 0.25 * x**2 - 0.7 * x**3

    np.testing.assert_allclose(cubic_spline(t, cubic(t), at), cubic(at), rtol=1e-9, atol=1e-9)
    t3 = np.array([0.0, 0.4, 1.5])
    np.testing.assert_allclose(cubic_spline(t3, 2 - t3 + 3 * t3**2, at), 2 - at + 3 * at**2, rtol=1e-12, atol=1e-11)


def test_too_few_points_or_mismatched_values_are_refused():
    with pytest.raises(ValueError, match="at least 2 points"):
        cubic_spline(np.array([0.0]), np.array([1.0]), np.array([0.5]))
    with pytest.raises(ValueError, match="at least 2 points"):
        cubic_spline(np.arange(4.0), np.arange(3.0), np.array([0.5]))


def test_reading_200hz_channels_onto_a_1khz_grid_does_not_load_scipy_interpolate(tmp_path):
    run = write_logger_run(tmp_path / "run.mf4", "mf4")  # its 200 Hz group is up-sampled onto the 1 kHz grid
    code = (
        "import json, sys; from vehid_cli.io.read import read_record; "
        f"rec = read_record({str(run)!r}, {dict(CHANNELS)!r}); "
        "print(json.dumps([rec.rates['acc_rr'], rec.rate, 'scipy.interpolate' in sys.modules]))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == [200.0, 1000.0, False]
