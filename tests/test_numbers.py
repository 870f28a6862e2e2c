"""The numbers do not move: the paper's campaigns, the bound, a damper campaign, the nonlinear car with every
effect, the bench effects and a diagnosis, bit for bit against the fingerprints recorded before the package was
reorganised (tests/golden.py says how they were made and when to re-record them)."""

from __future__ import annotations

import json

import pytest

from tests.golden import GOLDEN, compute


@pytest.fixture(scope="module")
def now() -> dict:
    return compute()


@pytest.mark.parametrize(
    "case",
    ["paper_abc_f2", "paper_hybrid_wls", "damper_bingham", "nonlinear_car", "bench_effects", "diagnose_asymmetric"],
)
def test_numbers_are_bit_identical_to_the_recorded_ones(now, case):
    recorded = json.loads(GOLDEN.read_text())
    assert now[case] == recorded[case]
