"""Statistical campaigns: N identification runs of one task, in parallel, resumable, bit-reproducible.

Run i identifies from its own noise realisation with its own optimizer stream (`experiment.run_streams`),
so its result depends only on the config, the seed and i: never on `--jobs`, on the executor (a local
process pool or a Dask cluster, `executor.py`) or on which runs were done before an interruption. Each
finished run is saved (atomically, fsynced) to a checkpoint directory beside the output before the campaign
goes on, and a restarted campaign picks those runs up; a damaged record is discarded (with a warning) and its
run redone, never trusted. The campaign file is written atomically, under a lock (`locking.py`) that keeps
two processes from running the same campaign into the same file.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import time
import zipfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from .. import __version__
from ..config import AnyConfig
from ..core.errors import InputError, quote
from ..core.files import atomic_path, read_regular, remove_stale_temporaries, write_error
from ..core.locking import exclusive
from ..core.provenance import git_commit
from ..core.store import check_integrity, open_results
from ..identify.convergence import optimum_offset
from ..identify.crlb import CramerRao
from ..identify.records import BOUND_TOL, Campaign, RunRecord, summarise
from ..identify.source import DataFiles, DataSource
from ..systems import System, build_system
from .executor import Executor, LocalExecutor
from .results import CAMPAIGN_KIND, campaign_file_digest, config_difference, read_campaign_h5, write_campaign_h5

Log = Callable[[str], None]


# ------------------------------------------------------------------------------------------ running


def identify_run(system: System, index: int) -> RunRecord:
    """Run `index` of a campaign (the unit of work the executors ship)."""
    return system.identify_run(index)


def campaign_key(config: AnyConfig, data_files: Sequence[str | Path] = ()) -> str:
    """Identity of a campaign's results: the resolved config, the data files' bytes and the code version
    (runs of different code are never mixed in one campaign)."""
    h = hashlib.sha256(f"{config.digest()} {__version__} {git_commit()}".encode())
    for path in data_files:
        h.update(Path(path).read_bytes())
    return h.hexdigest()


STAMP_LIMIT = 1 << 16  # bytes of a checkpoint's campaign.json (it holds one key)
RECORD_LIMIT = 64 << 20  # bytes of one run's record (its estimate, history and per-channel chi2)
MAX_RUNS = 1_000_000  # runs of one campaign: a larger count is a typo, never a campaign (nothing is sized by it)
_RECORD = re.compile(r"run-\d{5,}\.npz")
_TEMPORARY = re.compile(r"\..+\.tmp")


class Checkpoint:
    """Per-run records of an unfinished campaign, in a directory beside its output file.

    It holds `campaign.json`, `run-NNNNN.npz` and the temporaries of their atomic writes, all files. A directory
    found in it, or a checkpoint that is not a directory (a file, a symlink, a symlink loop), is an InputError
    naming it: never removed, nor followed."""

    def __init__(self, directory: Path, key: str, log: Log | None = None):
        self.directory = directory
        self.key = key
        self.log = log

    def _warn(self, message: str) -> None:
        if self.log is not None:
            self.log(f"warning: {message}")

    def _refuse(self, what: str) -> InputError:
        return InputError(f"{what}; remove it to start the campaign afresh", source=str(self.directory))

    def _entries(self) -> list[Path]:
        """The checkpoint's entries, [] when there is no checkpoint; InputError for what vehid did not put there."""
        d = self.directory
        if not os.path.lexists(d):
            return []
        if d.is_symlink() or not d.is_dir():
            raise self._refuse("is not a directory (a file or a symlink where vehid keeps a campaign's checkpoint)")
        try:
            entries = sorted(d.iterdir())
        except OSError as exc:
            raise self._refuse(f"cannot be read ({exc.strerror})") from None
        for path in entries:
            if path.is_dir() and not path.is_symlink():
                raise self._refuse(f"holds a directory '{path.name}', which vehid never makes there")
        return entries

    def open(self) -> dict[int, RunRecord]:
        """Read back the runs the directory holds (refusing another campaign's runs). A checkpoint without
        runs (a campaign that failed before finishing one) holds nothing to protect and is started afresh.
        Unfinished writes (temporary files a kill left) are removed; a record that does not read back whole
        (truncated, CRC error, wrong run, a field of the wrong type or shape) is discarded with a warning and its
        run is redone."""
        entries = self._entries()
        for tmp in [p for p in entries if _TEMPORARY.fullmatch(p.name)]:
            tmp.unlink()
        records = [p for p in entries if _RECORD.fullmatch(p.name)]
        if not records:
            self.remove()
            return {}
        stamp = self.directory / "campaign.json"
        try:
            meta = json.loads(read_regular(stamp, STAMP_LIMIT, "checkpoint stamp").decode("utf-8"))
        except (FileNotFoundError, InputError, UnicodeDecodeError, ValueError, RecursionError):
            raise self._refuse("checkpoint directory has no readable campaign.json") from None
        if not isinstance(meta, dict) or meta.get("key") != self.key:
            raise InputError(
                "checkpoint belongs to a different config or data file; remove it or choose another -o",
                source=str(self.directory),
            )
        done = {}
        for path in records:
            try:
                record = RunRecord.load(path, RECORD_LIMIT)
                if path.name != f"run-{record.index:05d}.npz":
                    raise ValueError(f"it holds run {record.index}")
            except (ValueError, KeyError, InputError, OSError, MemoryError, zipfile.BadZipFile) as exc:
                self.discard(path, f"{exc.__class__.__name__}: {exc}")
                continue
            done[record.index] = record
        return done

    def discard(self, path: Path, reason: str) -> None:
        """Remove a damaged record (its run is redone), with a warning naming it."""
        self._warn(f"{path}: damaged checkpoint record ({quote(reason, 160)[1:-1]}); discarded, the run is redone")
        with contextlib.suppress(FileNotFoundError):
            path.unlink()

    def save(self, record: RunRecord) -> None:
        """Persist one finished run (creating the checkpoint, stamped with the campaign key, on the first). A write
        that fails (a full disk, a read-only folder) leaves no checkpoint without runs behind."""
        created = False
        if not os.path.lexists(self.directory):
            try:
                self.directory.mkdir(parents=True)
            except OSError as exc:
                raise write_error(self.directory, exc) from None
            created = True
        try:
            if created:
                with atomic_path(self.directory / "campaign.json") as tmp:
                    tmp.write_text(json.dumps({"key": self.key}))
            record.save(self.directory / f"run-{record.index:05d}.npz")
        except BaseException:
            if created or not any(self.directory.glob("run-*.npz")):
                with contextlib.suppress(OSError, InputError):
                    self.remove()
            raise

    def remove(self) -> None:
        """Delete the checkpoint: its runs first, campaign.json last, so that a kill midway leaves one that still
        opens (stamped, with fewer runs or none), never runs without their stamp."""
        entries = self._entries()
        if not os.path.lexists(self.directory):
            return
        stamp = self.directory / "campaign.json"
        for path in entries:
            if path != stamp:
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
        with contextlib.suppress(FileNotFoundError):
            stamp.unlink()
        self.directory.rmdir()


def run_campaign(
    config: AnyConfig,
    data_file: DataFiles = None,
    *,
    jobs: int | None = None,
    executor: Executor | None = None,
    checkpoint_dir: Path | None = None,
    on_run: Callable[[int, int], None] | None = None,
    log: Log | None = None,
    system: System | None = None,
    checks: bool = True,
    unidentifiable: bool = False,
) -> Campaign:
    """Run every run of the configured campaign (resuming from `checkpoint_dir` if it holds some), for any system.

    The runs execute on `executor` (default: a `LocalExecutor(jobs)` for this campaign alone); each finished
    run is checkpointed before the next result is taken. `on_run(done, total)` reports progress; `log` receives
    warnings (damaged checkpoint records) and notes ("resumed N of M runs"). With `checks` (the default), measured
    data whose channels fail a check that makes any fit meaningless (a sign, a swap, a unit factor) is an InputError
    naming each channel, the evidence and the fix, before any run. Unknowns the data cannot separate
    (`System.unidentifiable`) are an InputError naming the free combination, unless `unidentifiable` (--force)."""
    system = system if system is not None else build_system(config, data_file)
    found = system.checks()
    if checks and found is not None and found.stopping:
        raise InputError(found.stop_message(), source=system.data_file)
    n_runs = system.runs
    if not 1 <= n_runs <= MAX_RUNS:
        raise InputError(f"a campaign has 1 to {MAX_RUNS} runs, got {n_runs}", key="identify.runs")
    start = time.perf_counter()
    bound = system.bound()  # before the runs: a bad experiment fails before any work
    free = _free_unknowns(system, bound, unidentifiable)
    key = campaign_key(config, system.data_files())
    checkpoint = Checkpoint(checkpoint_dir, key, log) if checkpoint_dir else None
    done = checkpoint.open() if checkpoint else {}
    for i, r in list(done.items()):
        if r.estimate.shape != (len(system.box.names),):
            checkpoint.discard(checkpoint.directory / f"run-{i:05d}.npz",
                               f"{r.estimate.size} estimates for {len(system.box.names)} unknowns")  # fmt: skip
            del done[i]
    done = {i: r for i, r in done.items() if i < n_runs}
    if done and log is not None:
        log(f"note: resumed {len(done)} of {n_runs} runs from {checkpoint_dir}")
    todo = [i for i in range(n_runs) if i not in done]
    if on_run:
        on_run(len(done), n_runs)

    def finished(record: RunRecord) -> None:
        done[record.index] = record
        if checkpoint:
            checkpoint.save(record)
        if on_run:
            on_run(len(done), n_runs)

    with contextlib.ExitStack() as stack:
        if executor is None:
            executor = stack.enter_context(LocalExecutor(jobs))
        results = executor.map_unordered(identify_run, system, todo)
        stack.callback(results.close)
        for record in results:
            finished(record)
    records = tuple(done[i] for i in range(n_runs))
    warnings = ([] if free is None else [f"run anyway (--force): {free}"]) + ([] if found is None else found.warnings())
    if not checks and found is not None and found.stopping:
        warnings.insert(0, "checks overridden (--no-checks): " + found.stop_message())
    if n_runs == 1 and system.box.truth is None:  # one fit on measured data: its interval comes from the bound there
        bound, note = single_fit_bound(system, records[0])
        warnings += note
    findings = system.conclude(records)
    box = system.box
    summary = summarise(
        box.names, box.truth, list(records), bound, time.perf_counter() - start, system.residual_samples
    )
    return Campaign(
        config=config, data_file=system.data_file, names=box.names, truth=box.truth, nominal=box.nominal,
        lower=box.lower, upper=box.upper, sigma=system.sigma, sigma_source=system.sigma_source, records=records,
        bound=bound, summary=summary, data_sha256=system.source.digest, system=system.name,
        findings=findings, data_files=system.data_files(), objective=system.objective_label(config),
        channels=system.channel_names, checks=() if found is None else tuple(found.to_json()), warnings=tuple(warnings),
    )  # fmt: skip


def _free_unknowns(system: System, bound: CramerRao, allowed: bool) -> str | None:
    """Why the data cannot separate the unknowns (`System.unidentifiable`): an InputError unless `allowed`."""
    free = system.unidentifiable(bound)
    if free is not None and not allowed:
        raise InputError(f"{free}; --force runs it anyway", source=system.config.source, key="identify.unknowns")
    return free


def single_fit_bound(system: System, record: RunRecord) -> tuple[CramerRao, list[str]]:
    """The interval of one fit on measured data: the bound at the estimate for the assumed noise, widened by
    sqrt(chi²) when the residual is larger than that noise (the residual's own variance: what `diagnose` uses
    too), with a note saying so; and a note when the estimate is not at its fit's optimum (`not_at_optimum`)."""
    bound = system.bound(record.estimate)
    R = max(system.residual_samples, 1)
    limit = 1.0 + 5.0 * np.sqrt(2.0 / R)
    notes = []
    if np.isfinite(record.chi2) and record.chi2 > limit:
        factor = float(np.sqrt(record.chi2))
        notes.append(
            f"the residual is {record.chi2:.3g} x the assumed noise power: the 95 % intervals are the bound's widened "
            f"by sqrt(chi2) = {factor:.3g} (the residual's own variance, as vehid diagnose reports them)"
        )
        bound = bound.widened(factor)
    offset = not_at_optimum(system, record, bound)
    return bound, notes + ([offset] if offset else [])


def not_at_optimum(system: System, record: RunRecord, bound: CramerRao) -> str | None:
    """What a user must know when one fit's estimate is not at the optimum of its fit (identify/convergence.py: a
    Gauss–Newton step from it of a standard deviation or more), or None: the unknowns on a bound held."""
    box, x = system.box, record.estimate
    held = np.minimum(x - box.lower, box.upper - x) <= BOUND_TOL * (box.upper - box.lower)
    with np.errstate(all="ignore"):  # an estimate where the model diverges: no step, no note
        offset = optimum_offset(system.problem(system.reference(0)), x, bound.sd, held)
    if offset is None:
        return None
    config = system.config
    return offset.describe(config.units(box.names), config.identify.algorithm.name, system.objective_label(config))


def check_same_campaign(output: Path, config: AnyConfig, data_file: DataFiles) -> None:
    """InputError (naming the first differences) if `output` holds a campaign of another config or data file."""
    diffs = config_difference(output, config, DataSource.resolve(config, data_file).digest)
    if diffs:
        shown = "; ".join(diffs[:3]) + (f"; and {len(diffs) - 3} more" if len(diffs) > 3 else "")
        raise InputError(
            f"holds a campaign of another config or data ({shown}); choose another -o, or --force to overwrite it",
            source=str(output),
        )


def saved_runs_note(output: Path) -> str:
    """What an interrupted campaign bound for `output` keeps, for the message after an interruption."""
    partial = checkpoint_dir_for(output)
    n = len(list(partial.glob("run-*.npz"))) if partial.is_dir() else 0
    if n == 0:
        return "no run had finished; nothing was written"
    return f"{n} finished run(s) saved in {partial}; run the same command again to resume"


def checkpoint_dir_for(output: Path) -> Path:
    """Where the finished runs of the campaign bound for `output` wait: `<output>.partial/`."""
    return output.with_name(output.name + ".partial")


def finished_campaign(output: Path, config: AnyConfig, data_file: DataFiles = None) -> Campaign | None:
    """The campaign `output` holds if it is whole (checksum verified) and of this campaign's key: the config (by
    `campaign_file_digest`, the test a sweep skips by), the data file's bytes and the code version; else None."""
    digest = DataSource.resolve(config, data_file).digest
    try:
        if check_integrity(output) is None or campaign_file_digest(output) != config.digest():
            return None
        with open_results(output, CAMPAIGN_KIND, "campaign file") as h5:
            made = tuple(str(h5.attrs.get(k, "")) for k in ("vehid_version", "git_commit", "data_sha256"))
        if made != (__version__, git_commit(), digest or ""):
            return None
        return read_campaign_h5(output)
    except (InputError, OSError):  # missing, damaged or foreign: not finished
        return None


def run_campaign_to_file(
    config: AnyConfig,
    output: Path,
    data_file: DataFiles = None,
    *,
    jobs: int | None = None,
    executor: Executor | None = None,
    on_run: Callable[[int, int], None] | None = None,
    log: Log | None = None,
    attrs: Mapping[str, str] | None = None,
    lock: bool = True,
    force: bool = False,
    checks: bool = True,
) -> Campaign:
    """Run (or resume) a campaign, write its HDF5 file atomically, then drop its checkpoint (kept if the write
    fails: the rerun finishes from it). A checkpoint beside a finished file of this campaign is stale: removed,
    and that file's campaign returned.

    With `lock` (the default) the output's lock is held throughout: `locking.Busy` (an InputError) if another
    process holds it. Pass `lock=False` only when the caller holds it. `attrs` are extra root attributes of the
    file (a sweep records its varied keys). An output file holding another campaign (another config or data) is
    an InputError naming the difference, unless `force`."""
    output = Path(output)
    if os.path.lexists(output) and not output.is_file():
        raise InputError(
            "is not a regular file (a directory, a FIFO or a broken symlink where the campaign file goes); remove it "
            "or choose another output",
            source=str(output),
        )
    data_file = DataSource.resolve(config, data_file)  # resolved once, passed down
    git_commit()  # asked (and cached) now, while the process is small: git spawned from a 220 MiB process (vfork) shows
    # its pages twice in the process tree's summed RSS until it has started (the 60 s record's peak read 436 MiB)
    with exclusive(output) if lock else contextlib.nullcontext():
        if output.exists() and not force:
            check_same_campaign(output, config, data_file)
        remove_stale_temporaries(output)
        partial = checkpoint_dir_for(output)
        if partial.is_dir():  # a kill during the clean-up after the file was written leaves a stale checkpoint
            finished = finished_campaign(output, config, data_file)
            if finished is not None:
                Checkpoint(partial, "").remove()
                if log is not None:
                    log(f"note: {output} is complete for this config; removed the stale checkpoint {partial}")
                return finished
        campaign = run_campaign(
            config,
            data_file,
            jobs=jobs,
            executor=executor,
            checkpoint_dir=partial,
            on_run=on_run,
            log=log,
            checks=checks,
            unidentifiable=force,
        )
        write_campaign_h5(output, campaign, attrs=attrs)
        Checkpoint(partial, "").remove()
    return campaign
