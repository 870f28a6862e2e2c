"""Assemble docs/results/dampers.md from real runs (make dampers): `vehid identify` on every config of
configs/dampers/, then `vehid report` for the tables and the force figures.

The tables and figures are the unedited output of `vehid report`; the discussion (DISCUSSION below) is
qualitative and written by hand. Usage: python make_dampers.py RUNS_DIR OUT.md [--reuse]
(--reuse keeps results files already in RUNS_DIR instead of identifying again).
"""

from __future__ import annotations

import datetime
import platform
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CONFIGS = ROOT / "configs" / "dampers"
DATASETS = {
    "mr_damper_labcontrol": (
        "MR damper (UTFPR Labcontrol), 0 V",
        ["mr_viscous", "mr_bingham", "mr_bouc_wen", "mr_generalized_bouc_wen"],
        "Trained on `ensaio1.1` (0 V, about 12.6 mm amplitude at 0.83 Hz, 30 s at 10 ms). Held out: `ensaio2.1`, "
        "`ensaio4.1`, `ensaio6.1`, the next runs of the same test series (same 30 s protocol and force level, "
        "amplitude falling and frequency rising step by step: about 11.8 mm at 0.87 Hz, 10.8 mm at 0.93 Hz, "
        "8.7 mm at 1.0 Hz), so they test whether a model extrapolates in amplitude and frequency while the coil "
        "and the rig stay as they were. The 0.88 V and the `.2` runs are left out: their coil voltage is "
        "undocumented or different, and no model here has a control input for it. Integration at 1 ms "
        "(10 substeps per 10 ms sample).",
    ),
    "friction_damper_brfd": (
        "Banded rotary friction damper (ARTS Lab), 36 lb band tension",
        ["brfd_bingham", "brfd_bingham_backlash", "brfd_bouc_wen", "brfd_bouc_wen_backlash"],
        "Trained on the 1 in / 0.5 Hz run, held out: the 0.5 in and 1.5 in runs at the same tension and "
        "frequency. For speed every file is windowed to 2-10 s (four cycles after the start-up) and decimated "
        "from 1024 Hz to 256 Hz; the integrator runs 4 substeps per sample (0.98 ms). The time column is printed "
        "with 7 significant digits, too few to be uniform at 1024 Hz, so the configs give `data.sample_rate` and "
        "the grid is rebuilt from it. Units in the files: in, in/s, kip. `_backlash` adds the dead zone `gap`.",
    ),
}


DISCUSSION = """
**MR damper.** The linear viscous model has no pre-yield region: in the force-velocity plane it is a straight
line where the measurement has a plateau and a loop, so it misses most of the force near the reversals; its J
is about the paper's value for its own (much better) models. Bingham's smoothed Coulomb term adds the plateau
and removes most of the error, but it is single-valued in velocity and cannot open the loop around zero
velocity. Bouc-Wen opens it and lowers J again; the generalised Bouc-Wen with separate compression and rebound
sets lowers it further, on the training run and on every held-out run, because the measured loops are not
symmetric (the rebound and compression branches differ). For every model the held-out J grows monotonically
from ensaio2.1 to ensaio6.1, i.e. with the distance in amplitude and frequency from the training run: some of
what the fit attributes to the model (notably the spring k1, x0 that absorbs the large force offset of this
rig) does not carry over, and a single training run cannot separate it. Both Bouc-Wen variants are stable with
RK4 at 1 ms, but their largest stable step is only slightly above 1 ms (the hysteretic states have a fast
mode), so 1 ms is close to the limit; the viscous and Bingham models are stable at any
step checked.

**Friction damper.** Bingham fails here: the fit leans on a stiff spring k1 and a very wide smoothing
velocity v_eps to imitate the pre-sliding slope at the reversals, which is amplitude-specific, so the held-out J
is several times the training J. Adding backlash helps Bingham a little, not enough. Bouc-Wen describes the
sticking-slipping transition as a hysteretic state and carries over to the other amplitudes far better.
Bouc-Wen with backlash is fitted in two stages (without the gap, then with it), so it can only match or beat
Bouc-Wen alone; it ends only marginally lower on every run: the hysteretic state already reproduces most of
what looked like a dead zone at the reversals, and the gap explains little more. (Fitted in one go from a
guessed gap, it had stopped in a worse local minimum.) No model captures two features visible in the figures:
the strong asymmetry between the compression and
tension force levels (the models are symmetric apart from the spring offset) and the chatter at the force peaks.
"""


def vehid(*args: str) -> str:
    res = subprocess.run([sys.executable, "-m", "vehid_cli", *args], capture_output=True, text=True, cwd=ROOT)
    if res.returncode != 0:
        sys.exit(f"vehid {' '.join(args)} failed:\n{res.stderr}")
    return res.stdout


def main() -> None:
    runs, out = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
    reuse = "--reuse" in sys.argv[3:]
    runs.mkdir(parents=True, exist_ok=True)
    figs = out.with_suffix("")  # docs/results/dampers/
    lines = [
        "# Semi-active and friction dampers identified on real measurements",
        "",
        f"Generated by `make dampers` on {datetime.date.today().isoformat()} ({platform.node()}, "
        f"{platform.machine()}): `vehid identify` on each config of `configs/dampers/`, then `vehid report`. "
        "Tables and figures are the tool's unedited output; the discussion at the end is written by hand.",
        "",
        "J is Fleps-Dezasse's Eq. 7: mean squared force error over the variance of the measured force (0 is a "
        "perfect fit, 1 is no better than the mean force). For scale, the paper reports J of about 0.09-0.10 "
        "on its own damper. Each fit is one bounded Nelder-Mead run from the configured start (budget in the "
        "config). The real-time check runs the identified model with fixed-step RK4 on the training motion; "
        "the real-time factor is simulated time over wall time on one core of this machine.",
        "",
    ]
    for dataset, (title, stems, how) in DATASETS.items():
        files = []
        for stem in stems:
            target = runs / f"{stem}.h5"
            if not (reuse and target.exists()):
                print(f"identify {stem} ...", flush=True)
                vehid("identify", str(CONFIGS / f"{stem}.yaml"), "-o", str(target))
            files.append(str(target))
        table = vehid("report", *files, "--format", "md")
        vehid("report", *files, "--plots", str(figs / dataset))
        lines += [f"## {title}", "", how, "", table, "### Force over time, displacement and velocity", ""]
        for png in sorted((figs / dataset).glob("*.png")):
            lines += [f"![{png.stem}]({png.relative_to(out.parent).as_posix()})", ""]
    lines += ["## Discussion", "", DISCUSSION.strip(), ""]
    out.write_text("\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
