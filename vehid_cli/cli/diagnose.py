"""`vehid diagnose`: close the loop on a declared model (fit, residual, candidates, re-fit) and give a verdict."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .common import (
    SaveConfigOption,
    SetOption,
    check_output_dir,
    check_writable,
    guarded,
    load_config,
    out,
    progress_bar,
    stage_hook,
    warn,
)


def _print_diagnosis(result) -> None:
    """The diagnosis on the terminal: its tables, each effect added (J and validation J before -> after), the
    notes and the verdict."""
    from ..report.diagnosis import diagnosis_tables

    out.print(diagnosis_tables(result))
    for step in result.steps:
        out.print(
            f"added {step.effect}: J {step.J_before:.4g} -> {step.J_after:.4g}, "
            f"validation J {step.validation_J_before:.4g} -> {step.validation_J_after:.4g}"
        )
    for note in result.notes:
        out.print(f"note: {note}", markup=False)
    out.print(f"verdict: {result.verdict} ({result.wall_s:.1f} s)")


@guarded
def diagnose(
    config: Annotated[
        Path, typer.Argument(metavar="CONFIG", help="Experiment config (YAML): the declared model.", show_default=False)
    ],
    data: Annotated[
        Optional[list[Path]],  # noqa: UP045
        typer.Option(
            "--data",
            metavar="FILE",
            help="Measurement file to fit and diagnose (a damper config may name it in data.file); repeat it to "
            "diagnose several runs of the car jointly (one parameter set).",
        ),
    ] = None,
    validate: Annotated[
        Optional[list[Path]],  # noqa: UP045
        typer.Option(
            "--validate", metavar="FILE", help="A run to judge the augmented model on (repeatable; else held-out data)."
        ),
    ] = None,
    json_out: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--json", metavar="FILE", help="Write the SPEC section 5 JSON here."),
    ] = None,
    plots: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(
            "--plots", metavar="DIR", help="Write figures here: residual before/after, fingerprint, spectrum."
        ),
    ] = None,
    html: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(
            "--html", metavar="FILE", help="Write one self-contained page (verdict, tables, figures, provenance)."
        ),
    ] = None,
    set_: SetOption = None,
    save_config: SaveConfigOption = None,
) -> None:
    """Close the loop: fit, analyse the residual, rank candidates (missing effects, mis-set known parameters),
    add the best, re-fit; say whether the residual is now at the noise.

    Full car: J is wls (chi2 per sample); the noise is estimated from the data unless --set noise.level=Np
    (or the config's noise.sigma) gives it; the integrator is rk4 unless the config sets newmark; any sensor
    layout and logger file the config describes; --data repeated fits several runs jointly. Damper on a
    bench: J is Eq. 7; the validation runs are --validate, else the config's data.validate. A candidate is
    accepted when its likelihood-ratio test is significant (p below 1e-3 / number of candidates), it lowers
    the validation J, and the data tell it from the runner-up; a known parameter that explains as much wins
    over an effect.
    The verdict starts with adequate, found, incomplete or inconclusive (data too short, noisy or unexcited).
    """

    from ..io.read import read_ahead

    if json_out is not None:
        check_writable(json_out, (".json",))
    if plots is not None:
        check_output_dir(plots, "--plots")
    if save_config is not None:
        check_writable(save_config, (".yaml", ".yml"))
    if html is not None:
        check_writable(html, (".html", ".htm"))
    runs = data or load_config(config, set_ or ()).data_runs()
    with read_ahead([*runs, *(validate or ())]):  # logger files read before the compiled kernels' imports
        from ..systems import diagnose_config

        with progress_bar("diagnose") as bar:  # a bar on a terminal; elsewhere a line per step with the time left
            progress = stage_hook(bar, {"candidates": "candidate", "fit": "fit"})
            result = diagnose_config(config, set_ or (), data or None, validate or (), log=warn, progress=progress)
    _print_diagnosis(result)
    _write_outputs(result, config, data or [], validate or [], set_ or (), json_out, plots, save_config, html)


def _write_outputs(result, config: Path, data: list[Path], validate: list[Path], sets, json_out, plots, save_config,
                   html) -> None:  # fmt: skip
    """The files a diagnosis was asked for: figures, JSON, the diagnosed config, the HTML page."""
    from ..core.jsonio import write_json
    from ..report.diagnosis import plot_diagnosis_files

    stem = (data[0] if data else config).stem
    if plots is not None:
        for path in plot_diagnosis_files(result, plots, stem):
            out.print(f"wrote {path}")
    if json_out is not None:
        write_json(json_out, result.to_json())
        out.print(f"wrote {json_out}")
    if save_config is not None:
        from ..config.save import save_config as write_saved
        from ..report.saved_config import diagnosis_found

        found = diagnosis_found(result, data)
        out.print(f"wrote {write_saved(config, sets, found, save_config, command='vehid diagnose')}")
    if html is not None:
        from ..report.html import diagnosis_facts, diagnosis_page, write_page

        facts = diagnosis_facts(config, sets, data, validate)
        write_page(html, diagnosis_page(result, facts, stem))
        out.print(f"wrote {html}")
