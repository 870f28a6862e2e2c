"""Issue 25: model uncertainty (library terms imitating a law they do not contain) and the bench's non-parametric law.

The unit checks here are fast: which strut element each library term acts on, the comparison of two explanations'
declared unknowns, and the bench law recovered from a force with a known law outside the library (a square-root
damper) and not found in pure noise. The loop's own cases (laws outside the library made by the independent
simulator) are in tests/test_diagnose_independent.py (slow).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from rich.console import Console

from vehid_cli.diagnose.bench_law import bench_law, eq7
from vehid_cli.diagnose.result import Diagnosis, ModelReport
from vehid_cli.diagnose.uncertainty import (
    compare_explanations,
    crowded_element,
    elements_of,
    fit_about_equally,
    widened,
)
from vehid_cli.report.diagnosis import diagnosis_tables
from vehid_cli.report.html import diagnosis_page


def test_each_term_acts_on_its_element_of_the_strut():
    assert elements_of("coulomb_friction") == ("velocity",)
    assert elements_of("asymmetric_damping") == ("velocity",)
    assert elements_of("progressive_spring") == ("deflection",)
    assert elements_of("parameter:cf") == ("velocity",)
    assert elements_of("parameter:kr") == ("deflection",)
    assert elements_of("parameter:ktr") == ()
    assert elements_of("tyre_damping") == ()


def test_terms_crowd_on_one_element_only_when_two_or_more_share_it():
    assert crowded_element(["coulomb_friction", "parameter:cr", "parameter:ktr"]) == (
        "velocity", ("coulomb_friction", "parameter:cr"),
    )  # fmt: skip
    assert crowded_element(["asymmetric_damping", "progressive_spring"]) is None
    assert crowded_element(["parameter:kf", "parameter:cr"]) is None
    assert crowded_element(["hysteresis", "tyre_damping"]) is None


def fake_unexplained(names, values, ci, samples=None, chi2_after=None):
    return SimpleNamespace(names=tuple(names), unknowns=np.asarray(values, float), dx_ci=np.asarray(ci, float),
                           samples=samples, chi2_after=chi2_after)  # fmt: skip


def test_explanations_that_disagree_beyond_their_intervals_widen_them_to_cover_both():
    names = ("m", "Ix")
    x, ci = np.array([1292.0, 517.0]), np.array([1.5, 5.0])
    alt = fake_unexplained(names, [1300.0, 519.0], [3.0, 6.0])
    mu = compare_explanations(["coulomb_friction", "parameter:cr", "parameter:cf"], names, x, ci, alt)
    assert mu is not None and mu.imitates and mu.worst == "m" and mu.trigger == "crowded"
    np.testing.assert_allclose(mu.separation, [8.0 / np.hypot(1.5, 3.0), 2.0 / np.hypot(5.0, 6.0)])
    # the selected interval grown by the spread on either side, joined with the alternative's
    np.testing.assert_allclose(mu.low, [1292.0 - 1.5 - 8.0, 517.0 - 5.0 - 2.0])
    np.testing.assert_allclose(mu.high, [1300.0 + 3.0, 519.0 + 6.0])
    out = mu.to_json()
    assert out["reason"] == "library terms imitate a law they do not contain"
    assert out["ci95_model_uncertainty"]["m"] == [1282.5, 1303.0]
    misfit = compare_explanations(["coulomb_friction", "parameter:cr"], names, x, ci, alt, ci_misfit=[12.0, 1.0])
    np.testing.assert_allclose(misfit.low, [1292.0 - 12.0 - 8.0, 510.0])  # the wider misfit interval of m, Ix's own
    np.testing.assert_allclose(misfit.high, [1292.0 + 12.0 + 8.0, 525.0])
    np.testing.assert_allclose(misfit.separation, mu.separation)  # the test itself assumes the model
    agree = compare_explanations(["coulomb_friction", "parameter:cr"], names, x, ci, fake_unexplained(names, x, ci))
    assert agree is not None and not agree.imitates
    assert compare_explanations(["coulomb_friction"], names, x, ci, alt) is None  # one term: nothing to compare


def test_the_struts_own_rates_are_reported_but_not_judged():
    """The non-parametric strut force shares the linear part of the strut's law out with g and h, so kr means
    something else beside it: a kr apart alone (the four-post rig's progressive spring, a library law) is no
    imitation; a body parameter apart is; with only strut rates declared they are all there is to judge."""
    names = ("m", "Ix", "kr", "cf")
    x, ci = np.array([1300.0, 500.0, 80000.0, 2800.0]), np.array([1.5, 5.0, 300.0, 9.0])
    strut_only = fake_unexplained(names, [1300.1, 500.2, 70000.0, 2475.0], [1.5, 5.0, 250.0, 9.0])
    mu = compare_explanations(["progressive_spring", "parameter:kr"], names, x, ci, strut_only)
    assert mu is not None and mu.separation[2] > 10 and not mu.imitates
    assert mu.to_json()["judged_on"] == ["m", "Ix"]
    body = fake_unexplained(names, [1310.0, 500.2, 80000.0, 2800.0], [1.5, 5.0, 250.0, 9.0])
    mu = compare_explanations(["progressive_spring", "parameter:kr"], names, x, ci, body)
    assert mu.imitates and mu.worst == "m"
    rates = ("kr", "cf")
    only = compare_explanations(["progressive_spring", "parameter:kr"], rates, x[2:], ci[2:],
                                fake_unexplained(rates, [70000.0, 2475.0], [250.0, 9.0]))  # fmt: skip
    assert only.imitates and only.worst == "kr"


def test_several_unknowns_judged_together_need_a_wider_separation():
    """Bonferroni over the unknowns judged: the threshold is z(2.5 % / n) / z(2.5 %) intervals (the normal quantiles
    from the standard library, independent of diagnose/tails), so an unknown 1.01 intervals apart among five (a
    progressive spring the library holds) is no disagreement, while one alone is."""
    from statistics import NormalDist

    from vehid_cli.diagnose.uncertainty import apart

    z = NormalDist().inv_cdf
    for n in (1, 2, 5, 9):
        assert apart(n) == pytest.approx(z(1 - 0.025 / n) / z(0.975), rel=1e-9)
    names = ("m", "Ix", "Iy", "a1", "b1")
    x, ci = np.full(5, 100.0), np.ones(5)
    near = x + np.array([0.0, 0.0, 0.0, 1.01 * np.sqrt(2.0), 0.0])
    mu = compare_explanations(["progressive_spring", "parameter:kf"], names, x, ci, fake_unexplained(names, near, ci))
    assert mu.separation[3] == pytest.approx(1.01) and not mu.imitates
    one = compare_explanations(["progressive_spring", "parameter:kf"], ("a1",), x[:1], ci[:1],
                               fake_unexplained(("a1",), near[3:4], ci[:1]))  # fmt: skip
    assert one.imitates and one.to_json()["threshold"] == 1.0


def test_the_widened_interval_holds_a_truth_that_both_explanations_miss():
    """Two explanations biased the same way, each interval missing the truth (the weak square-root damper's m: 1303.6
    ± 1.6 and 1307.5 ± 3.0 for 1300): the union misses it too, the widened interval holds it."""
    truth, x, alt = 1300.0, np.array([1303.6]), np.array([1307.5])
    ci, alt_ci = np.array([1.6]), np.array([3.0])
    low, high = widened(x, ci, alt, alt_ci)
    assert min(x - ci, alt - alt_ci)[0] > truth  # the union of the two intervals misses it
    assert low[0] <= truth <= high[0]
    assert low[0] <= (alt - alt_ci)[0] and high[0] >= (alt + alt_ci)[0] and high[0] >= (x + ci)[0]


def test_one_term_is_compared_when_the_non_parametric_force_fits_about_as_well():
    """The equal-fit trigger: the non-parametric force's excess R (J_alt - J_sel) against chi²(k) at 5 %; for k = 2
    the critical value is -2 ln 0.05 (the chi²(2) survival function is exp(-x/2))."""
    names = ("m",)
    R, J = 20000, 1.01
    margin = -2.0 * np.log(0.05)
    for excess, equal in ((margin - 0.5, True), (margin + 0.5, False), (-40.0, True)):
        alt = fake_unexplained(names, [1310.0], [3.0], samples=R, chi2_after=J + excess / R)
        assert fit_about_equally(J, 2, alt)[0] is equal
        np.testing.assert_allclose(fit_about_equally(J, 2, alt)[1:], [excess, margin], rtol=1e-9)
        mu = compare_explanations(["sqrt_like_effect"], names, [1295.0], [2.0], alt, fit=(J, 2))
        assert (mu is not None) is equal
        if equal:
            assert mu.trigger == "equal fit" and mu.imitates
            assert ("fit worse than the non-parametric" if excess < -margin else "fit about equally") in mu.summary()
            assert mu.to_json()["trigger"] == "equal fit"
    assert compare_explanations([], names, [1295.0], [2.0], alt, fit=(J, 2)) is None  # nothing selected


def test_every_output_marks_the_model_based_the_misfit_and_the_widened_intervals():
    """A diagnosis whose selected terms imitate a law: the verdict says so, the JSON carries ci95 (the model assumed),
    ci95_misfit and ci95_model_uncertainty side by side, the terminal table and the HTML page mark each kind."""
    names = ("m", "Ix")
    x, ci = np.array([1292.0, 517.0]), np.array([1.5, 5.0])
    terms = ("coulomb_friction", "parameter:cr")
    mu = compare_explanations(terms, names, x, ci, fake_unexplained(names, [1300.0, 519.0], [3.0, 6.0]))
    before = ModelReport((), names, x - 10.0, ci, 4.0, 4.0, 4.1, 5.0)
    after = ModelReport(terms, (*names, "cr"), np.append(x, 3800.0), np.append(ci, 20.0), 1.01, 1.01, 1.02, 0.5,
                        ci_misfit=np.array([2.0, 6.0, 25.0]))  # fmt: skip
    d = Diagnosis(before, after, (), terms, 0.05, "held-out blocks", "estimated", 1.0, chi2_limit=1.05,
                  model_uncertainty=mu)  # fmt: skip
    assert d.verdict.startswith("incomplete: library terms imitate a law they do not contain"), d.verdict
    out = d.to_json()
    assert out["after"]["ci95"]["m"] == [1290.5, 1293.5]
    assert out["after"]["ci95_misfit"]["m"] == [1290.0, 1294.0]
    assert out["after"]["ci95_model_uncertainty"]["m"] == [float(mu.low[0]), float(mu.high[0])]
    assert out["model_uncertainty"]["trigger"] == "crowded"
    console = Console(width=80, record=True)
    console.print(diagnosis_tables(d))
    text = console.export_text()
    assert "m 95 % (misfit)" in text and "m 95 % (model unc.)" in text
    assert "(model unc.): 95 % covering" in text and "assuming the model right" in text
    html = diagnosis_page(d, {}, figures=False)
    assert "(model unc.)" in html and "(misfit)" in html and "imitate a law they do not contain" in html


def test_a_found_verdict_says_when_the_loop_stopped_on_two_candidates_it_could_not_tell_apart():
    names = ("m",)
    rep = ModelReport(("parameter:kf",), names, np.array([1300.0]), np.array([2.0]), 1.0, 1.0, 1.0, 0.1)
    note = "cannot tell parameter:kr (LR 40) from parameter:ktr (LR 41) apart on these data: neither added"
    d = Diagnosis(rep, rep, (), ("parameter:kf",), 0.05, "", "", 0.0, notes=(note,), chi2_limit=1.05)
    assert d.verdict.startswith("found: parameter:kf; the residual is now at the noise")
    assert d.verdict.endswith(f"(then stopped: {note})")
    plain = Diagnosis(rep, rep, (), ("parameter:kf",), 0.05, "", "", 0.0, chi2_limit=1.05).verdict
    assert plain.startswith("found") and "then stopped" not in plain


def bench_run(amplitude, frequency, law, seed, n=2000, dt=0.005, noise=5.0):
    t = np.arange(n) * dt
    w = 2 * np.pi * frequency
    x, v = amplitude * np.sin(w * t), amplitude * w * np.cos(w * t)
    model = 800.0 * v + 2000.0 * x  # what the fitted model gives
    force = model + law(v) + noise * np.random.default_rng(seed).standard_normal(n)
    return {"force": force, "model": model, "displacement": x, "velocity": v, "control": np.zeros(n)}


def sqrt_law(v):
    return 150.0 * np.sign(v) * np.sqrt(np.abs(v) / 0.1)


def test_the_bench_law_recovers_a_square_root_damper_and_lowers_the_held_out_J():
    train = bench_run(0.02, 1.5, sqrt_law, 1)
    held = {"a": bench_run(0.015, 2.0, sqrt_law, 2), "b": bench_run(0.01, 1.0, sqrt_law, 3)}
    law = bench_law(train, held)
    assert law.significant and law.lowers_validation
    for name, h in held.items():  # independent truth: the held-out J of the model is Eq. 7 of the law's force
        assert law.validation_per_file[name][0] == eq7(h["force"], h["model"])
    # the oracle: the model plus the true law leaves only the noise; the estimated law comes close to it
    oracle = np.mean([eq7(h["force"], h["model"] + sqrt_law(h["velocity"])) for h in held.values()])
    assert law.validation_J_non_parametric <= 3.0 * oracle, (law.validation_J_non_parametric, oracle)
    assert law.validation_J_parametric >= 20 * oracle
    assert law.dominant.variable == "velocity"


def test_no_bench_law_in_pure_noise():
    train = bench_run(0.02, 1.5, lambda v: 0.0 * v, 4)
    law = bench_law(train, {"a": bench_run(0.015, 2.0, lambda v: 0.0 * v, 5)})
    assert not law.significant


def test_misfit_intervals_keep_the_residuals_correlation():
    """The sandwich intervals of a fit whose residual is correlated (a line through AR(1) errors, rho 0.9) against the
    exact covariance of least squares under that correlation, (X'X)^-1 X' Sigma X (X'X)^-1: within the sampling
    error of 30 blocks, where the white-noise intervals are 4x too narrow."""
    from vehid_cli.diagnose.attribution import Fit, fisher_ci, misfit_ci
    from vehid_cli.optimizers.base import Problem

    n, rho = 3000, 0.9
    t = np.linspace(0.0, 1.0, n)
    rng = np.random.default_rng(5)
    e = np.zeros(n)
    w = rng.standard_normal(n) * np.sqrt(1 - rho**2)
    for i in range(1, n):
        e[i] = rho * e[i - 1] + w[i]
    y = 1.0 + 2.0 * t + e
    X = np.column_stack([np.ones(n), t])

    def residuals(P):
        R = y[None, :] - P @ X.T
        return np.mean(R**2, axis=1), R

    problem = Problem(np.array([-10.0, -10.0]), np.array([10.0, 10.0]), lambda P: residuals(P)[0], residuals, 1.0,
                      ("a", "b"))  # fmt: skip
    x = np.linalg.lstsq(X, y, rcond=None)[0]
    fit = Fit(("a", "b"), x, float(np.mean((y - X @ x) ** 2)), 0)
    Sigma = rho ** np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    inv = np.linalg.inv(X.T @ X)
    exact = 1.959963984540054 * np.sqrt(np.diag(inv @ X.T @ Sigma @ X @ inv))
    got = misfit_ci(problem, fit)
    white = fisher_ci(problem, x, fit.J)
    assert np.all(white < 0.4 * exact), (white, exact)
    assert np.all((got > 0.6 * exact) & (got < 1.5 * exact)), (got, exact)
