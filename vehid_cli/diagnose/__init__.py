"""Close the loop (issue 6): residual analysis, attribution of the residual to a missing effect, and the
augmentation loop that adds it and re-fits (``vehid diagnose``), for the car (`loop.diagnose`) and for a damper
on a bench (`damper.diagnose_damper`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from ..config import DamperConfig, load_config
from ..core.errors import InputError
from ..systems.base import configured_data_file, data_paths
from ..systems.damper.diagnosis import diagnose_damper
from .loop import Diagnosis, diagnose

CAR_DEFAULTS = ("identify.objective=wls", "noise.level=0")  # the car's loop: wls, noise estimated from the data


def diagnose_config(
    config: str | Path,
    overrides: Sequence[str] = (),
    data: str | Path | Sequence[str | Path] | None = None,
    validate: Sequence[str | Path] = (),
    log: Callable[[str], None] | None = None,
) -> Diagnosis:
    """`vehid diagnose`: the config's system closes the loop on `data` (the car: one run, or several fitted
    jointly, else the config's data.files; a damper: one run, or its config's data.file), judged on the `validate`
    runs (the car takes one; a damper's default is its data.validate). The car's runs may be any sensor layout
    and logger files (config layout and data sections)."""
    cfg = load_config(config, overrides)
    files = data_paths(data)
    if isinstance(cfg, DamperConfig):
        if len(files) > 1:
            raise InputError("a damper is diagnosed on one --data run (its validation runs: --validate)",
                             source=str(config))  # fmt: skip
        return diagnose_damper(cfg, files[0] if files else None, tuple(validate) or None, log=log)
    files = data_paths(configured_data_file(cfg, files))  # --data wins over the config's runs, as for identify
    if not files:
        raise InputError("diagnose needs --data FILE (the measured run to fit) or data.files", source=str(config))
    if len(validate) > 1:
        raise InputError("the full car takes one --validate run", source=str(config))
    cfg = load_config(config, [*CAR_DEFAULTS, *overrides])  # the user's --set comes last and wins
    return diagnose(cfg, files[0] if len(files) == 1 else files, validate[0] if validate else None, log=log)


__all__ = ["Diagnosis", "diagnose", "diagnose_config", "diagnose_damper"]
