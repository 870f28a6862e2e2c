"""The car's campaign figures: the sensors' responses, convergence, RE boxes, true against estimated values."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.figures import plt, save
from ...identify.experiment import SimulatedRun
from ...identify.task import JointTask, Task, build_tasks
from . import report as tables
from .fitted import ChannelFit, campaign_fits
from .report import grouped

FAMILY_AXES = {"disp": ("mm", 1e3), "acc": ("m/s²", 1.0)}  # the unit each family is drawn in, and its scale from SI


def plot_responses(run: SimulatedRun, path: str | Path, model: str = "clean (configured car)") -> None:
    """Road inputs and every channel of the layout, measured (noisy) over clean: displacements left, accelerations
    right (for the paper's layout, z1..z4 and z1''..z4'': Gökdağ Fig. 4)."""
    exp = run.experiment
    t = exp.t
    families = [f for f in ("disp", "acc") if f in run.channels]
    rows = max(len(exp.layout.names(f)) for f in families)
    fig, axes = plt.subplots(
        rows + 1, 2, figsize=(11, 2.2 * (rows + 1)), sharex=True,
        constrained_layout=True, squeeze=False,
    )  # fmt: skip
    for corner in range(4):
        axes[0, 0].plot(t, 100 * exp.road[:, corner], label=f"road{corner + 1}")
    axes[0, 0].set_ylabel("road [cm]")
    axes[0, 0].legend(ncol=4, fontsize=8)
    axes[0, 1].axis("off")
    axes[0, 1].text(
        0.0, 0.5,
        f"{exp.config.source}\nnoise {exp.config.noise.describe()}\n"
        f"integrator: {exp.config.simulation.integrator}, dt = {1e3 * exp.dt:g} ms",
        va="center", fontsize=10,
    )  # fmt: skip
    for col, family in enumerate(families):
        unit, scale = FAMILY_AXES[family]
        names = exp.layout.names(family)
        for row in range(rows):
            ax = axes[row + 1, col]
            if row >= len(names):
                ax.axis("off")
                continue
            noisy, clean = run.channels[family][:, row], run.clean_channels[family][:, row]
            if not np.array_equal(noisy, clean):
                ax.plot(t, scale * noisy, lw=0.5, color="0.6", label="measured (noisy)")
            ax.plot(t, scale * clean, lw=1.2, color="C0", label=model)
            ax.set_ylabel(f"{names[row]} [{unit}]")
            if row == 0:
                ax.legend(fontsize=8, loc="upper right")
    for col in range(len(families), axes.shape[1]):
        for row in range(1, rows + 1):
            axes[row, col].axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle("Responses of the sensors to the road input")
    save(fig, path)


def first_task(campaign) -> Task:
    """The identification task of a campaign's (first) run, rebuilt from its config and data files."""
    files = campaign.data_files or (() if campaign.data_file is None else (campaign.data_file,))
    task = build_tasks(campaign.config, files)
    return task.tasks[0] if isinstance(task, JointTask) else task


# ------------------------------------------------------------------------------------------ campaign figures


def _best_cost_on_grid(record, grid):
    """Best cost so far at each evaluation count of `grid` (a step function of the run's history)."""
    idx = np.searchsorted(record.history_evals, grid, side="right") - 1
    out = np.where(idx >= 0, record.history_cost[np.clip(idx, 0, None)], np.nan)
    return out


def plot_convergence(group, path: str | Path) -> None:
    """Best cost against evaluations: median over runs and the 10-90 % band, one curve per algorithm."""
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    for i, c in enumerate(group):
        recorded = [r for r in c.records if r.history_evals.size]
        first = max(int(r.history_evals[0]) for r in recorded)  # every run has a best cost from here on
        top = max(int(r.history_evals[-1]) for r in recorded)
        grid = np.unique(np.linspace(first, max(top, first), 200).astype(int))
        curves = np.array([_best_cost_on_grid(r, grid) for r in c.records])
        med = np.nanmedian(curves, axis=0)
        lo, hi = np.nanpercentile(curves, [10, 90], axis=0)
        color = f"C{i}"
        ax.plot(grid, med, color=color, label=c.config.identify.algorithm.name)
        ax.fill_between(grid, lo, hi, color=color, alpha=0.2, lw=0)
    ax.set_yscale("log")
    ax.set_xlabel("model evaluations")
    ax.set_ylabel(f"best {group[0].config.identify.objective}")
    ax.set_title("Convergence: median over runs, 10–90 % band")
    ax.legend()
    save(fig, path)


def plot_re_boxes(group, path: str | Path) -> None:
    """Per-run RE of each parameter, a box per algorithm, with the Cramér–Rao ±1 sd band shaded; each panel's title
    gives the truth in the parameter's unit."""
    names = group[0].names
    fig, axes = plt.subplots(1, len(names), figsize=(3 * len(names), 4), constrained_layout=True, squeeze=False)
    for j, name in enumerate(names):
        ax = axes[0, j]
        data = [c.summary.per_run_re_percent[:, j] for c in group]
        ax.boxplot(data, tick_labels=[c.config.identify.algorithm.name for c in group])
        bound = group[0].bound.re_sd_percent[j]
        if bound < 1e3:
            ax.axhspan(-bound, bound, color="C2", alpha=0.2, lw=0, label="CRLB ±1 sd")
        ax.axhline(0, color="0.3", lw=0.8)
        unit = group[0].units[name]
        ax.set_title(f"{name}, truth {group[0].truth[j]:g} {unit}".rstrip(), fontsize=10)
        ax.set_ylabel("RE per run [%]")
        ax.tick_params(axis="x", rotation=45)
    axes[0, 0].legend(fontsize=8)
    save(fig, path)


def plot_true_vs_estimated(campaign, path: str | Path) -> None:
    """Bounce, pitch and roll of the true car and of the mean estimate (the paper's Fig. 5), on the (first) run."""
    exp = first_task(campaign).experiment
    values = dict(zip(campaign.names, campaign.summary.mean, strict=True))
    est = exp.simulate({k: [v] for k, v in values.items()})
    ref = exp.simulate()
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True, constrained_layout=True)
    for ax, (label, i, scale, unit) in zip(
        axes, (("bounce x", 0, 1e3, "mm"), ("pitch θ", 2, 1e3, "mrad"), ("roll φ", 1, 1e3, "mrad")), strict=True
    ):
        truth_label = "configured car" if campaign.truth is None else "true car"
        ax.plot(exp.t, scale * ref.q[:, i], color="C0", lw=1.5, label=truth_label)
        ax.plot(exp.t, scale * est.q[0, :, i], color="C3", lw=1.0, ls="--", label="mean estimate")
        ax.set_ylabel(f"{label} [{unit}]")
    axes[0].legend()
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"True and estimated responses ({campaign.config.identify.algorithm.name})")
    save(fig, path)


def plot_noisy_vs_clean(campaign, path: str | Path) -> None:
    """The data run 0 identified from (its first measured run), over the clean channels (the paper's Fig. 4): of the
    configured car for simulated data (their truth), of the fitted car (run 0's estimate) for measured data."""
    task = first_task(campaign)
    exp = task.experiment
    fitted = campaign.data_file is not None
    values = {n: [v] for n, v in zip(campaign.names, campaign.records[0].estimate, strict=True)} if fitted else None
    clean = exp.simulate(values) if fitted else exp.simulate()
    model = exp.read(clean)
    if fitted:  # a batch of one
        model = {f: v[0] for f, v in model.items()}
    data = task.measured if task.measured is not None else task.reference(0)
    channels = {f: data.get(f, model[f]) for f in model}
    if task.offsets:  # the channels' offsets are unknowns: draw the data with the offsets that fit it best removed
        objective = task.objective({f: channels[f] for f in task.families})
        channels.update({f: model[f] + objective.error(f, model[f]) for f in task.families})
    run = SimulatedRun(exp, clean, model, channels, task.sigma, campaign.config.noise.level)
    plot_responses(run, path, "fitted car (the estimate)" if fitted else "clean (configured car)")


def plot_fitted(label: str, fits: list[ChannelFit], path: str | Path) -> None:
    """Per channel (a row each, worst fitted first): measured and fitted time histories, the residual with the
    noise's ±1 sigma band, and the residual's amplitude spectral density against the noise floor of that sigma."""
    fig, axes = plt.subplots(len(fits), 3, figsize=(14, 2.1 * len(fits) + 0.8), squeeze=False,
                             constrained_layout=True, gridspec_kw={"width_ratios": [2.2, 2.2, 1.4]})  # fmt: skip
    for row, f in zip(axes, fits, strict=True):
        unit, scale = FAMILY_AXES[f.family]
        row[0].plot(f.t, scale * f.measured, lw=0.6, color="0.55", label="measured")
        row[0].plot(f.t, scale * f.fitted, lw=1.0, color="C3", label="fitted model")
        row[0].set_ylabel(f"{f.name} [{unit}]")
        row[1].plot(f.t, scale * f.residual, lw=0.6, color="C0")
        row[1].axhspan(-scale * f.sigma, scale * f.sigma, color="C2", alpha=0.2, lw=0, label="±1 sigma (noise)")
        row[1].set_ylabel(f"residual [{unit}]")
        row[1].set_title(f"{f.name}: chi²/sample {f.chi2_per_sample:.3g}", fontsize=9)
        row[2].loglog(f.freq[1:], scale * f.asd[1:], lw=0.8, color="C0", label="residual")
        row[2].axhline(scale * f.floor, color="C2", ls="--", lw=1, label="noise floor")
        row[2].set_ylabel(f"ASD [{unit}/√Hz]")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    axes[-1, 2].set_xlabel("frequency [Hz]")
    for j in range(3):
        axes[0, j].legend(fontsize=8, loc="upper right")
    fig.suptitle(f"Measured against fitted, worst channel first: {label}")
    save(fig, path)


def write_fitted_plots(campaign, stem: str, out_dir: Path) -> list[Path]:
    """fitted_<stem>.png (a measured run: fitted_<stem>_run<i>.png each, several runs) for a measured-data
    campaign."""
    runs = campaign_fits(campaign)
    written = []
    for i, (label, fits) in enumerate(runs, start=1):
        p = out_dir / (f"fitted_{stem}.png" if len(runs) == 1 else f"fitted_{stem}_run{i}.png")
        plot_fitted(label, fits, p)
        written.append(p)
    return written


def write_campaign_plots(campaigns, files, out_dir: str | Path) -> list[Path]:
    """All figures for a set of campaign files; returns the paths written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    stems = {id(c): Path(f).stem for c, f in zip(campaigns, files, strict=True)}
    if len(set(stems.values())) < len(stems):  # same file names from different directories
        stems = {id(c): f"{Path(f).parent.name}_{Path(f).stem}" for c, f in zip(campaigns, files, strict=True)}
    for g, group in enumerate(grouped(campaigns)):
        cfg = group[0].config
        tag = f"{cfg.identify.objective}_{cfg.sensors}_np{cfg.noise.level:g}"
        if any(tables.group_key(other[0])[3:] != tables.group_key(group[0])[3:] for other in grouped(campaigns)):
            tag += f"_g{g}"  # groups that differ in data file or unknowns must not overwrite each other
        p = out_dir / f"convergence_{tag}.png"
        plot_convergence(group, p)
        written.append(p)
        if group[0].truth is not None:
            p = out_dir / f"re_boxes_{tag}.png"
            plot_re_boxes(group, p)
            written.append(p)
        p = out_dir / f"responses_{tag}.png"
        plot_noisy_vs_clean(group[0], p)
        written.append(p)
        for c in group:
            p = out_dir / f"true_vs_estimated_{stems[id(c)]}.png"
            plot_true_vs_estimated(c, p)
            written.append(p)
            if c.data_file is not None:
                written.extend(write_fitted_plots(c, stems[id(c)], out_dir))
    return written
