"""Which campaigns may share a report: the comparability rule, from the provenance each file records.

Two campaigns are comparable when they identified the same experiment with the same code:

- **config**: their resolved configs differ only in *method keys* (`identify.algorithm.*`,
  `identify.objective`, `identify.runs`, `identify.seed`, `identify.budget`, `identify.start`, `sensors`,
  `noise.level`: what the tables put side by side) or in keys a sweep varied (each campaign file of a sweep
  records its `--vary` keys). A different car, road, time grid, unknown set, search box or truth is not
  comparable unless a sweep varied it. For dampers the model and everything under `identify` are method keys
  too (models side by side on one bench test); the bench, the data and the noise are the experiment.
- **data**: both simulated, or both identified from the same data file (same name and same SHA-256 of its
  bytes).
- **code**: the same vehid version and git commit (when both are known), and the same NumPy, SciPy and numba
  versions (those that set the numbers). Host, time and executor do not matter: results are bit-identical
  wherever they ran.

`vehid report` refuses incomparable campaigns (exit 2, naming the two files and what differs) unless
`--allow-mixed` is given.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..campaign.results import CAMPAIGN_KIND, stored_attributes, stored_yaml
from ..config import flatten
from ..core.errors import InputError
from ..core.store import open_results
from ..systems import SYSTEMS, System

METHOD_KEYS = System.method_keys  # a system's own: System.method_keys
CODE_KEYS = ("vehid_version", "git_commit", "numpy_version", "scipy_version", "numba_version")
_MISSING = object()


@dataclass(frozen=True)
class Provenance:
    """What a campaign file records about where its numbers came from."""

    file: str
    config: dict
    config_sha256: str
    data_file: str
    data_sha256: str
    code: dict[str, str]
    varied: frozenset[str]  # keys the sweep that wrote it varied (empty for `vehid identify`)


def read_provenance(path: str | Path) -> Provenance:
    """The provenance attributes of a campaign file (InputError for a file that is not one)."""
    source = str(path)
    r = stored_attributes(open_results(path, CAMPAIGN_KIND, "campaign file"), source)
    config = stored_yaml(r.text("config_yaml"), source)
    return Provenance(
        file=source,
        config=config if isinstance(config, dict) else {},
        config_sha256=r.text("config_sha256", ""),
        data_file=r.text("data_file", ""),
        data_sha256=r.text("data_sha256", ""),
        code={k: r.text(k) for k in CODE_KEYS if k in r.h5.attrs},
        varied=frozenset(r.json_list("sweep_vary", str)),
    )


def method_keys(p: Provenance) -> tuple[str, ...]:
    """The method keys of a stored campaign's system (another system's campaign: the common ones)."""
    cls = SYSTEMS.get(str(p.config.get("system", "vehicle")))
    return METHOD_KEYS if cls is None else cls.method_keys


def _covered(key: str, allowed) -> bool:
    return any(key == a or key.startswith(a + ".") for a in allowed)


def _show(value) -> str:
    return "(absent)" if value is _MISSING else json.dumps(value)


def differences(a: Provenance, b: Provenance) -> list[str]:
    """What makes two campaigns incomparable (empty if they are comparable), each as 'what (a vs b)'."""
    out = []
    fa, fb = flatten(a.config), flatten(b.config)
    allowed = set(method_keys(a)) & set(method_keys(b)) | a.varied | b.varied
    for key in sorted(set(fa) | set(fb)):
        va, vb = fa.get(key, _MISSING), fb.get(key, _MISSING)
        if va != vb and not _covered(key, allowed):
            out.append(f"{key} ({_show(va)} vs {_show(vb)})")
    if (a.data_file, a.data_sha256) != (b.data_file, b.data_sha256):

        def data(p: Provenance) -> str:
            return f"{p.data_file} (sha256 {p.data_sha256[:12]})" if p.data_file else "simulated"

        out.append(f"data ({data(a)} vs {data(b)})")
    for key in CODE_KEYS:
        va, vb = a.code.get(key), b.code.get(key)
        if va is None or vb is None or (key == "git_commit" and "unknown" in (va, vb)):
            continue
        if va != vb:
            out.append(f"{key} ({va} vs {vb})")
    return out


def incomparable(provenances: Sequence[Provenance]) -> list[tuple[Provenance, Provenance, list[str]]]:
    """Every file that is not comparable with the first one, with what differs."""
    if not provenances:
        return []
    first = provenances[0]
    return [(first, p, d) for p in provenances[1:] if (d := differences(first, p))]


def check_comparable(files: Sequence[str | Path], allow_mixed: bool = False) -> list[str]:
    """InputError naming two incomparable files and what differs, unless `allow_mixed`; then the same
    findings are returned as notes (one per incomparable file)."""
    found = incomparable([read_provenance(f) for f in files])
    notes = [f"{b.file} differs from {a.file} in {', '.join(d)}" for a, b, d in found]
    if found and not allow_mixed:
        a, b, d = found[0]
        more = f" ({len(found) - 1} more file(s) differ too)" if len(found) > 1 else ""
        raise InputError(
            f"campaigns are not comparable: {a.file} and {b.file} differ in {', '.join(d)}, which no sweep varied"
            f"{more}; report them separately, or pass --allow-mixed to put them in one report anyway"
        )
    return notes
