"""Values rounded to their uncertainty (core.digits): two significant digits of the uncertainty, the value to the
same decimal place; the cases without a usable uncertainty."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vehid_cli.core.digits import DASH, interval, place, rounded, significant, with_uncertainty


@pytest.mark.parametrize(
    ("value", "unc", "text"),
    [
        (1234.5678, 12.345, "1235 ± 12"),
        (0.012345, 0.00067, "0.01235 ± 0.00067"),
        (1500.0, 0.5, "1500.00 ± 0.50"),
        (-3.14159, 0.0123, "-3.142 ± 0.012"),
        (123456.0, 1234.0, "123500 ± 1200"),
        (0.0004, 0.0099, "0.0004 ± 0.0099"),
        (2.5e7, 3.04e5, "2.500e+07 ± 3.0e+05"),
        (1.23456e-9, 2.1e-11, "1.235e-09 ± 2.1e-11"),
        (-0.0001, 0.5, "0.00 ± 0.50"),  # no "-0.00"
        (0.0996, 0.0996, "0.100 ± 0.100"),  # the uncertainty rounds up to the next decade: 0.0996 -> 0.100
    ],
)
def test_the_value_keeps_the_decimal_place_of_two_digits_of_its_uncertainty(value, unc, text):
    assert with_uncertainty(value, unc) == text


@pytest.mark.parametrize("value", [1234.5678, 0.012345, -7.77e-4, 3.3e8, 9.99])
@pytest.mark.parametrize("unc", [12.345, 0.00067, 3e-6, 4.4e6, 0.5])
def test_rounded_text_is_the_value_within_half_its_last_digit(value, unc):
    """An independent check: the printed numbers differ from the full ones by at most half a unit of their last
    digit, and the uncertainty keeps exactly two significant digits."""
    v, u = rounded(value, unc)
    last = 10.0 ** place(unc)
    assert abs(float(v) - value) <= 0.5 * last * (1 + 1e-9)
    assert abs(float(u) - unc) <= 0.5 * last * (1 + 1e-9)
    shown = math.floor(math.log10(float(u))) - place(unc) + 1  # digits from the leading one to the last shown
    assert shown == 2 or (shown == 3 and float(u) == 10 ** math.floor(math.log10(float(u))))  # or it rounded up
    if "e" not in u and "." in u:  # a fixed-point text shows exactly down to that digit
        assert len(u.split(".")[1]) == -place(unc)


@pytest.mark.parametrize("unc", [0.0, float("nan"), float("inf"), None])
def test_an_uncertainty_that_is_zero_nan_or_infinite_leaves_the_value_at_six_digits(unc):
    v, u = rounded(1234.56789, unc)
    assert v == "1234.57"
    assert u == ("0" if unc == 0.0 else DASH)
    assert with_uncertainty(1234.56789, unc) == ("1234.57 ± 0" if unc == 0.0 else "1234.57")


def test_a_missing_value_is_a_dash_and_intervals_round_both_ends():
    assert rounded(float("nan"), 1.0)[0] == DASH and rounded(None, None) == (DASH, DASH)
    assert significant(None) == DASH and significant(np.float64(2.0)) == "2"
    assert interval(1222.2, 1247.8) == "[1222, 1248]"  # half-width 12.8 -> units
    assert interval(0.01168, 0.01302) == "[0.01168, 0.01302]"
    assert interval(float("nan"), 1.0) == DASH
