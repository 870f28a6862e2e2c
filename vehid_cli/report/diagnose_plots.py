"""Figures of a diagnosis (``vehid diagnose --plots DIR``): the residual before and after the loop, its
fingerprint binned against the strut (or stroke) velocity and deflection, and its spectrum. Residuals are
in units of the noise sigma the data implies, so white noise sits at ±1 and its spectrum at 1."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.figures import plt
from ..core.figures import save as _save
from ..identify.records import worst_first

SCALE = {"m": ("mm", 1e3), "m/s^2": ("m/s²", 1.0)}  # channels drawn in another unit than their SI one: (unit, factor)


def _label(report, name: str) -> str:
    return f"{name}: {', '.join(report.effects) or 'declared model'} (J = {report.J:.3g})"


def plot_diagnosis(diagnosis, directory: str | Path, stem: str = "diagnose") -> list[Path]:
    """Write <stem>-residual.png, <stem>-fingerprint.png, <stem>-spectrum.png, <stem>-channels.png (every channel
    measured against the fits before and after, worst first) and, when the residual stayed above the noise,
    <stem>-unexplained.png (the estimated missing strut force); return their paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    before, after = diagnosis.before.analysis, diagnosis.after.analysis
    if before is None:
        return []
    changed = diagnosis.after is not diagnosis.before
    sides = [("before", diagnosis.before, before, "0.55")] + (
        [("after", diagnosis.after, after, "C3")] if changed else []
    )
    # the channel that the declared model misses most (of the first run, when several were fitted jointly)
    ch = int(np.argmax(before.chi2_channel))
    name = before.channels[ch]
    paths = []

    fig, ax = plt.subplots(figsize=(10, 3.6), constrained_layout=True)
    t = np.arange(before.residual.shape[0]) * (before.dt or 1.0)
    for side, report, an, colour in sides:
        own = np.isfinite(an.residual[:, ch])  # a slow channel: its own samples
        ax.plot(t[own], an.residual[own, ch], lw=0.6, color=colour, label=_label(report, side))
    ax.axhspan(-1, 1, color="C0", alpha=0.12, label="±1 sigma (the noise)")
    ax.set_xlabel("t [s]" if before.dt else "sample")
    ax.set_ylabel(f"residual {name} [sigma]")
    ax.set_title(f"residual of {name}, before and after the loop")
    ax.legend(fontsize=8, loc="upper right")
    paths.append(_save(fig, directory / f"{stem}-residual.png"))

    corners = before.fingerprint
    fig, axes = plt.subplots(len(corners), 2, figsize=(10, 2.6 * len(corners) + 0.6), squeeze=False,
                             constrained_layout=True)  # fmt: skip
    for i in range(len(corners)):
        for j in range(2):
            ax = axes[i, j]
            for side, _report, an, colour in sides:
                b = an.fingerprint[i][j]
                err = 2.0 / np.sqrt(np.maximum(b.count, 1))
                scale = 1e3 if b.variable != "velocity" else 1.0
                ax.errorbar(scale * b.centres, b.mean, yerr=err, color=colour, marker="o", ms=3, lw=1,
                            capsize=2, label=side)  # fmt: skip
            ax.axhline(0.0, color="k", lw=0.5)
            unit = "m/s" if corners[i][j].variable == "velocity" else "mm"
            where = f"corner {i + 1} " if len(corners) > 1 else ""
            ax.set_xlabel(f"{where}{corners[i][j].variable} [{unit}]")
            ax.set_ylabel("mean residual [sigma]")
            if i == 0 and j == 0:
                ax.legend(fontsize=8)
    fig.suptitle("fingerprint: residual binned against the strut's motion (±2 standard errors)")
    paths.append(_save(fig, directory / f"{stem}-fingerprint.png"))

    if before.psd is not None:
        fig, ax = plt.subplots(figsize=(8, 3.6), constrained_layout=True)
        for side, report, an, colour in sides:
            ax.semilogy(an.freq[1:], an.psd[ch, 1:], color=colour, label=_label(report, side))
        ax.axhline(1.0, color="C0", ls="--", lw=1, label="white noise of the implied sigma")
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel(f"PSD of residual {name} / white level")
        ax.set_title("spectral residual")
        ax.legend(fontsize=8)
        paths.append(_save(fig, directory / f"{stem}-spectrum.png"))
    if before.fitted is not None:
        paths.append(plot_channels(diagnosis, directory / f"{stem}-channels.png"))
    if getattr(diagnosis, "unexplained", None) is not None:
        paths.append(plot_unexplained(diagnosis.unexplained, directory / f"{stem}-unexplained.png"))
    return paths


def channel_order(analysis) -> list[int]:
    """The channels of a residual analysis, worst fitted (largest chi² per sample) first."""
    chi2 = {name: float(v) for name, v in zip(analysis.channels, analysis.chi2_channel, strict=True)}
    return [analysis.channels.index(n) for n in worst_first(chi2)]


def plot_channels(diagnosis, path: str | Path) -> Path:
    """Every channel (a row each, worst fitted before the loop first): measured with the model before and after the
    loop, the residual before and after, and its spectrum before and after over the noise floor of the channel's
    sigma (1: white noise of that sigma)."""
    before, after = diagnosis.before.analysis, diagnosis.after.analysis
    changed = diagnosis.after is not diagnosis.before
    order = channel_order(before)
    fig, axes = plt.subplots(len(order), 3, figsize=(14, 2.1 * len(order) + 0.8), squeeze=False,
                             constrained_layout=True, gridspec_kw={"width_ratios": [2.2, 2.2, 1.4]})  # fmt: skip
    t = np.arange(before.residual.shape[0]) * (before.dt or 1.0)
    sides = [("before", diagnosis.before, before, "0.35", "--")]
    sides += [("after", diagnosis.after, after, "C3", "-")] if changed else []
    for row, j in zip(axes, order, strict=True):
        unit, scale = SCALE.get(before.units[j], (before.units[j], 1.0)) if before.units else ("-", 1.0)
        own = np.isfinite(before.residual[:, j])
        row[0].plot(t[own], scale * before.measured[own, j], lw=0.6, color="0.65", label="measured")
        for side, report, an, colour, style in sides:
            label = _label(report, side)
            row[0].plot(t[own], scale * an.fitted[own, j], lw=1.0, color=colour, ls=style, label=label)
            row[1].plot(t[own], scale * an.sigma[j] * an.residual[own, j], lw=0.6, color=colour, label=side)
            if an.psd is not None:
                row[2].semilogy(an.freq[1:], an.psd[j, 1:], lw=0.8, color=colour, label=side)
        row[1].axhspan(-scale * before.sigma[j], scale * before.sigma[j], color="C2", alpha=0.2, lw=0,
                       label="±1 sigma (noise)")  # fmt: skip
        row[2].axhline(1.0, color="C2", ls="--", lw=1, label="noise floor")
        name = before.channels[j]
        row[0].set_ylabel(f"{name} [{unit}]")
        row[1].set_ylabel(f"residual [{unit}]")
        row[1].set_title(f"{name}: chi²/sample {before.chi2_channel[j]:.3g}"
                         + (f" -> {after.chi2_channel[j]:.3g}" if changed else ""), fontsize=9)  # fmt: skip
        row[2].set_ylabel("PSD / noise floor [-]")
    for ax in axes[-1, :2]:
        ax.set_xlabel("t [s]" if before.dt else "sample")
    axes[-1, 2].set_xlabel("frequency [Hz]")
    for ax in axes[0]:
        ax.legend(fontsize=7, loc="upper right")
    fig.suptitle("Measured against the model before and after the loop, worst channel first")
    return _save(fig, path)


def plot_bench_law(law, path: str | Path) -> Path:
    """Write a damper's missing force law on its bench (``diagnose.bench_law``): force [N] over each variable with its
    95 % band, and the held-out J of the parametric model beside the model plus the law, per held-out run."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = len(law.curves)
    fig, axes = plt.subplots(1, n + 1, figsize=(4.2 * (n + 1), 3.8), squeeze=False, constrained_layout=True)
    for ax, c in zip(axes[0], law.curves, strict=False):
        scale, unit = (1e3, "mm") if c.variable == "displacement" else (1.0, "m/s" if c.variable == "velocity" else "-")
        x = c.grid * scale
        ax.fill_between(x, c.band[0], c.band[1], color="C0", alpha=0.2, lw=0, label="95 % band")
        ax.plot(x, c.force, color="C0", lw=1.5, label="estimate")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"{c.variable} [{unit}]")
        ax.set_ylabel("missing force [N]")
        ax.set_title(f"f({c.variable}){'' if c.significant else ': nothing significant'}", fontsize=9)
        ax.legend(fontsize=8)
    ax = axes[0, n]
    per = law.validation_per_file or {"held out": (law.validation_J_parametric, law.validation_J_non_parametric)}
    names = list(per)
    pos = np.arange(len(names))
    ax.bar(pos - 0.2, [per[k][0] for k in names], 0.4, label="parametric model", color="0.55")
    ax.bar(pos + 0.2, [per[k][1] for k in names], 0.4, label="+ non-parametric law", color="C3")
    ax.set_xticks(pos, names, rotation=30, fontsize=8)
    ax.set_ylabel("held-out J (Eq. 7)")
    ax.legend(fontsize=8)
    fig.suptitle(
        f"unexplained damper force: training J {law.J_before:.3g} -> {law.J_after:.3g}, held-out J "
        f"{law.validation_J_parametric:.3g} -> {law.validation_J_non_parametric:.3g}, edf {law.edf:.1f}",
        fontsize=10,
    )
    return _save(fig, path)


def plot_unexplained(unexplained, path: str | Path) -> Path:
    """Write the estimated missing strut force (``diagnose.unexplained``) as a 2x2 figure: front/rear x force [N]
    over deflection [mm] and over velocity [m/s], each with its 95 % band and the closest library shape; a damper's
    law on its bench (it has `curves`) by plot_bench_law."""
    if hasattr(unexplained, "curves"):
        return plot_bench_law(unexplained, path)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(10, 7), squeeze=False, constrained_layout=True)
    for i, axle in enumerate((unexplained.front, unexplained.rear)):
        for j, curve in enumerate((axle.g, axle.h)):
            ax = axes[i, j]
            deflection = curve.variable == "deflection"
            x = curve.grid * (1e3 if deflection else 1.0)
            ax.fill_between(x, curve.band[0], curve.band[1], color="C0", alpha=0.2, lw=0, label="95 % band")
            ax.plot(x, curve.force, color="C0", lw=1.5, label="estimate")
            res = curve.resembles
            shape = res.best.replace("_", " ")
            ax.axhline(0.0, color="k", lw=0.5)
            ax.axvline(0.0, color="k", lw=0.5)
            ax.set_xlabel(f"{axle.axle} {'deflection [mm]' if deflection else 'velocity [m/s]'}")
            ax.set_ylabel("missing force [N]")
            what = f"{axle.axle} {'g(d)' if deflection else 'h(v)'}"
            if curve.significant:
                ax.set_title(f"{what}: like {shape} (R² = {res.r2[res.best]:.2f})", fontsize=9)
            else:
                ax.set_title(f"{what}: nothing significant (closest: {shape})", fontsize=9)
            if i == 0 and j == 0:
                ax.legend(fontsize=8)
    fig.suptitle(
        f"unexplained strut force: chi² per sample {unexplained.chi2_before:.3g} -> {unexplained.chi2_after:.3g}, "
        f"edf {unexplained.edf:.1f}, p = {max(unexplained.p_value, 1e-300):.2g}; closest library shape: "
        f"{unexplained.resembles.replace('_', ' ')}",
        fontsize=10,
    )
    return _save(fig, path)
