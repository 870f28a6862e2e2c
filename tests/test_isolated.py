"""A parsing library run in a child process (a fresh interpreter: vehid_cli/core/isolated.py, issues 22 and 26): its
result comes back, and a crash, a hang, a memory blow-up or an exception of the library becomes `Damaged` in the
parent, which lives on and prints nothing of the child's."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from vehid_cli.core.errors import InputError
from vehid_cli.core.errors import clip as quoted
from vehid_cli.core.isolated import Damaged, in_child


def _arrays(n):
    return {"t": np.arange(n) / 10.0, "name": "ACC"}


def test_the_result_comes_back_from_the_child():
    out = in_child(_arrays, 1000)
    np.testing.assert_array_equal(out["t"], np.arange(1000) / 10.0)
    assert out["name"] == "ACC"


def _crash(sig):
    os.write(2, b"malloc(): invalid size\n")
    os.kill(os.getpid(), sig)


@pytest.mark.parametrize("sig, name", [(signal.SIGSEGV, "SIGSEGV"), (signal.SIGABRT, "SIGABRT")])
def test_a_crash_of_the_library_is_damaged_and_prints_nothing(capfd, sig, name):
    with pytest.raises(Damaged, match=f"the reader crashed \\({name}"):
        in_child(_crash, sig)
    captured = capfd.readouterr()
    assert "malloc" not in captured.err + captured.out


def _hang():
    while True:
        pass


def test_a_hang_is_cut_after_the_timeout():
    with pytest.raises(Damaged, match="did not finish within 1 s"):
        in_child(_hang, timeout=1.0)


def _allocate():
    return np.ones(2**40)  # 8 TiB


def test_a_declared_size_beyond_the_memory_budget_is_damaged_with_the_numbers():
    with pytest.raises(Damaged) as info:
        in_child(_allocate)
    assert "memory budget" in info.value.reason and "GiB" in info.value.reason


def _library_error():
    raise KeyError("x" * 100_000)


def test_an_exception_of_the_library_is_damaged_quoting_at_most_200_characters():
    with pytest.raises(Damaged) as info:
        in_child(_library_error)
    assert info.value.reason.startswith("KeyError: ")
    assert len(info.value.reason) < 300


def _input_error():
    raise InputError("no channel 'X'", source="run.mf4", key="acc")


def test_an_input_error_raised_in_the_child_reaches_the_parent_as_it_was():
    with pytest.raises(InputError) as info:
        in_child(_input_error)
    assert (info.value.detail, info.value.source, info.value.key) == ("no channel 'X'", "run.mf4", "acc")


def test_quoted_cuts_long_text():
    assert quoted("short") == "short"
    assert quoted("y" * 1000).startswith("y" * 200 + "...") and "1000 characters" in quoted("y" * 1000)
