"""Close the loop (issue 6): residual analysis, attribution of the residual to a missing effect, and the
augmentation loop that adds it and re-fits (``vehid diagnose``), for the car (`loop.diagnose`) and for a damper
on a bench (`damper.diagnose_damper`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from ..config import DamperConfig, load_config
from ..errors import InputError
from .damper import diagnose_damper
from .loop import Diagnosis, diagnose

CAR_DEFAULTS = ("identify.objective=wls", "noise.level=0")  # the car's loop: wls, noise estimated from the data


def diagnose_config(
    config: str | Path,
    overrides: Sequence[str] = (),
    data: str | Path | None = None,
    validate: Sequence[str | Path] = (),
    log: Callable[[str], None] | None = None,
) -> Diagnosis:
    """`vehid diagnose`: the config's system closes the loop on `data` (a damper config may name it in data.file),
    judged on the `validate` runs (the car takes one; a damper's default is its data.validate)."""
    cfg = load_config(config, overrides)
    if isinstance(cfg, DamperConfig):
        return diagnose_damper(cfg, data, tuple(validate) or None, log=log)
    if data is None:
        raise InputError("diagnose needs --data FILE (the measured run to fit)", source=str(config))
    if len(validate) > 1:
        raise InputError("the full car takes one --validate run", source=str(config))
    if cfg.layout is not None or cfg.data.channels or cfg.data.files:
        raise InputError(
            "diagnose works on the paper's corner layout (acc1..acc4, disp1..disp4) and one measurement CSV so far; "
            "this config has a sensor layout or logger channels (layout, data.channels, data.files): identify it "
            "with `vehid identify`",
            source=str(config),
            key="layout" if cfg.layout is not None else "data",
        )
    cfg = load_config(config, [*CAR_DEFAULTS, *overrides])  # the user's --set comes last and wins
    return diagnose(cfg, data, validate[0] if validate else None, log=log)


__all__ = ["Diagnosis", "diagnose", "diagnose_config", "diagnose_damper"]
