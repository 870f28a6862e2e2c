"""Numbers shown as far as their uncertainty supports them: two significant digits of the uncertainty and the value
to the same decimal place (the GUM's convention: 1234.5678 ± 12.345 is "1235 ± 12"). For tables people read (the
terminal, Markdown, LaTeX, HTML); files for machines (JSON, CSV, HDF5) keep every digit."""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

DASH = "–"  # a figure that does not exist (None, NaN)
SCIENTIFIC_ABOVE = 1e7  # a value or uncertainty this large, or a last digit below 1e-6, is written with an exponent
SCIENTIFIC_PLACE = -7


def _finite(x) -> bool:
    return x is not None and math.isfinite(float(x))


def place(uncertainty: float, digits: int = 2) -> int:
    """The decimal exponent of the last digit shown for this (positive, finite) uncertainty: that of its
    `digits`-th significant digit (0.00067 -> -5, 12.3 -> 0, 1234 -> 2)."""
    return math.floor(math.log10(abs(uncertainty))) - digits + 1


def _quantized(x: float, at: int) -> Decimal:
    """x rounded half-up at decimal exponent `at` (from its shortest repr, so 0.012345 rounds to 0.01235)."""
    return Decimal(repr(float(x))).quantize(Decimal(1).scaleb(at), rounding=ROUND_HALF_UP)


def _fixed(x: float, at: int) -> str:
    q = _quantized(x, at)
    text = str(int(q)) if at >= 0 else format(q, "f")
    return text[1:] if text.startswith("-") and float(q) == 0 else text  # no "-0"


def _scientific(x: float, at: int) -> str:
    q = float(_quantized(x, at))
    exponent = math.floor(math.log10(abs(q))) if q != 0 else at
    return f"{q:.{max(exponent - at, 0)}e}"


def significant(value, digits: int = 6) -> str:
    """A number without an uncertainty (a configured value, a truth, a ratio): `digits` significant digits."""
    return f"{float(value):.{digits}g}" if _finite(value) else DASH


def rounded(value, uncertainty, digits: int = 2) -> tuple[str, str]:
    """(value, uncertainty) as text: the uncertainty to `digits` significant digits and the value to the same decimal
    place. An uncertainty of zero gives (6 significant digits, "0"); NaN, infinite or None gives (6 significant
    digits, "–"); a value of NaN or None gives "–"."""
    if not _finite(value):
        return DASH, DASH if not _finite(uncertainty) else significant(uncertainty, digits)
    if not _finite(uncertainty) or float(uncertainty) == 0:
        return significant(value), "0" if _finite(uncertainty) else DASH
    unc = abs(float(uncertainty))
    at = place(unc, digits)
    if at < SCIENTIFIC_PLACE or max(abs(float(value)), unc) >= SCIENTIFIC_ABOVE:
        return _scientific(value, at), _scientific(unc, at)
    return _fixed(value, at), _fixed(unc, at)


def with_uncertainty(value, uncertainty, digits: int = 2) -> str:
    """ "1235 ± 12": `rounded`, joined (the value alone when there is no uncertainty)."""
    v, u = rounded(value, uncertainty, digits)
    return v if u == DASH else f"{v} ± {u}"


def interval(low, high, digits: int = 2) -> str:
    """ "[1223, 1247]": both ends to the decimal place of `digits` significant digits of the half-width."""
    if not (_finite(low) and _finite(high)):
        return DASH
    half = (float(high) - float(low)) / 2
    if half <= 0:
        return f"[{significant(low)}, {significant(high)}]"
    (lo, _), (hi, _) = rounded(low, half, digits), rounded(high, half, digits)
    return f"[{lo}, {hi}]"
