"""The HDF5 store's reading side (issue 22): a campaign file is parsed in a child process, and what it holds is
validated before it is trusted, also when its checksum was recomputed after an edit."""

from __future__ import annotations

import os
import shutil
import signal
import time

import h5py
import numpy as np
import pytest

import vehid_cli.core.h5snapshot as snapshot
from tests.conftest import small_config
from vehid_cli.campaign.results import read_campaign_h5, write_campaign_h5
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.core.errors import InputError
from vehid_cli.core.store import USERBLOCK, check_integrity, open_results, stamp_checksum

TINY = ("simulation.duration=0.5", "simulation.dt=0.005", "identify.algorithm.population=4",
        "identify.algorithm.iterations=2", "identify.runs=2")  # fmt: skip


@pytest.fixture(scope="module")
def campaign_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("store") / "c.h5"
    write_campaign_h5(path, run_campaign(small_config(*TINY), jobs=1))
    return path


def edited(campaign_file, tmp_path, edit) -> str:
    """A copy of the campaign file edited through HDF5, its checksum recomputed (it passes the check)."""
    path = tmp_path / "edited.h5"
    shutil.copy(campaign_file, path)
    with h5py.File(path, "r+") as h5:
        edit(h5)
    stamp_checksum(path)
    assert check_integrity(path) is not None
    return str(path)


def replace(name, value):
    def edit(h5):
        del h5[name]
        h5[name] = value

    return edit


def set_attr(name, value):
    def edit(h5):
        h5.attrs[name] = value

    return edit


EDITS = {
    "bounds as strings": (replace("bounds", np.array([["0.7", "1.3"]] * 5, dtype=h5py.string_dtype())), "bounds"),
    "a NaN data_file": (set_attr("data_file", np.nan), "data_file"),
    "config_yaml a number": (set_attr("config_yaml", 5), "config_yaml"),
    "config_yaml an alias bomb": (set_attr("config_yaml", "a: &a [x, x]\nb: [*a, *a]\n"), "aliases"),
    "estimates of the wrong length": (replace("runs/estimate", np.ones((2, 4))), "runs/estimate"),
    "estimates not finite": (replace("runs/estimate", np.full((2, 5), np.nan)), "runs/estimate"),
    "no runs": (replace("runs/estimate", np.ones((0, 5))), "no run"),
    "a truth of zero": (replace("truth", np.zeros(5)), "truth"),
    "the bound a group": (replace("crlb/fisher", np.ones(3)), "crlb/fisher"),
    "system unknown": (set_attr("system", "toaster"), "system"),
    "checks deep JSON": (set_attr("checks", "[" * 100_000 + "]" * 100_000), "checks"),
    "kind an array": (set_attr("kind", np.array(["vehid.campaign"] * 3, dtype=h5py.string_dtype())), "kind"),
    "a count of 2**34 samples": (
        lambda h5: (
            h5.__delitem__("runs/cost"),
            h5.create_dataset("runs/cost", shape=(2**34,), dtype="f8", chunks=(1024,)),
        ),
        "runs/cost",
    ),
    "a soft-link loop": (replace("nominal", h5py.SoftLink("/nominal")), "nominal"),
    "an external link": (replace("truth", h5py.ExternalLink("elsewhere.h5", "/x")), "truth"),
}


@pytest.mark.parametrize("what", list(EDITS))
def test_an_edited_campaign_file_with_a_valid_checksum_is_refused_naming_the_part(campaign_file, tmp_path, what):
    edit, part = EDITS[what]
    path = edited(campaign_file, tmp_path, edit)
    with pytest.raises(InputError, match="edited.h5") as caught:
        read_campaign_h5(path)
    assert part in str(caught.value) and len(str(caught.value)) < 600, str(caught.value)


def test_a_cycle_of_hard_links_is_read_once(campaign_file, tmp_path):
    def edit(h5):
        h5["runs/back"] = h5  # the root again, inside /runs

    path = edited(campaign_file, tmp_path, edit)
    tree = open_results(path, "vehid.campaign", "campaign file")
    with pytest.raises(InputError, match="already read"):
        tree["runs/back"]
    assert read_campaign_h5(path).summary.mean.shape == (5,)  # the rest is whole


def test_a_plain_hdf5_copy_without_the_user_block_still_reads(campaign_file, tmp_path):
    path = tmp_path / "plain.h5"
    path.write_bytes(campaign_file.read_bytes()[USERBLOCK:])
    assert check_integrity(path) is None
    np.testing.assert_array_equal(read_campaign_h5(path).summary.mean, read_campaign_h5(campaign_file).summary.mean)


def test_a_fifo_in_place_of_a_campaign_file_is_refused_at_once(tmp_path):
    fifo = tmp_path / "c.h5"
    os.mkfifo(fifo)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="not a regular file"):
        read_campaign_h5(fifo)
    assert time.perf_counter() - t0 < 5


def _hang(path, budget):
    """A reader that never finishes (module level: the reader's child is a fresh interpreter, core/isolated.py)."""
    time.sleep(60)


def _segfault(path, budget):
    """A reader that crashes."""
    os.kill(os.getpid(), signal.SIGSEGV)


def test_a_reader_that_hangs_or_crashes_is_an_input_error_naming_the_file(campaign_file, monkeypatch):
    """What HDF5 does on some crafted metadata (a flipped byte in the root's attribute storage loops forever, others
    segfault): the child is killed after the timeout, or seen dying by its signal; vehid goes on."""
    monkeypatch.setattr(snapshot, "_read", _hang)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="did not finish within 1 s") as caught:
        snapshot.read_tree(campaign_file, "campaign file", timeout=1.0)
    assert str(campaign_file) in str(caught.value) and time.perf_counter() - t0 < 10
    monkeypatch.setattr(snapshot, "_read", _segfault)
    with pytest.raises(InputError, match="crashed .SIGSEGV."):
        snapshot.read_tree(campaign_file, "campaign file")
    monkeypatch.undo()
    assert snapshot.read_tree(campaign_file, "campaign file")["runs/estimate"].shape == (2, 5)
