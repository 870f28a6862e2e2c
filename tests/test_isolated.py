"""A parsing library run in a child process (a fresh interpreter: vehid_cli/core/isolated.py, issues 22 and 26): its
result comes back, and a crash, a hang, a memory blow-up or an exception of the library becomes `Damaged` in the
parent, which lives on and prints nothing of the child's."""

from __future__ import annotations

import os
import signal
import struct

import numpy as np
import pytest

from vehid_cli.core.errors import InputError
from vehid_cli.core.errors import clip as quoted
from vehid_cli.core.isolated import Damaged, _receive, in_child


def _arrays(n):
    return {"t": np.arange(n) / 10.0, "name": "ACC"}


def test_the_result_comes_back_from_the_child():
    out = in_child(_arrays, 1000)
    np.testing.assert_array_equal(out["t"], np.arange(1000) / 10.0)
    assert out["name"] == "ACC"


def _shared_and_odd():
    t = np.arange(50_000) / 1e3
    return {"a": (np.sin(t), t), "b": (np.cos(t), t), "strided": np.arange(12.0)[::3], "empty": np.zeros(0),
            "ints": np.arange(7, dtype=np.int32), "text": "µm/s²"}  # fmt: skip


def test_arrays_come_back_equal_one_object_shared_and_strided_or_empty_ones_too():
    out = in_child(_shared_and_odd)
    t = np.arange(50_000) / 1e3
    np.testing.assert_array_equal(out["a"][0], np.sin(t))
    np.testing.assert_array_equal(out["b"][1], t)
    assert out["a"][1] is out["b"][1]  # sent once, one object here as there
    np.testing.assert_array_equal(out["strided"], [0.0, 3.0, 6.0, 9.0])
    assert out["empty"].shape == (0,) and out["ints"].dtype == np.int32 and out["text"] == "µm/s²"


def _received(*chunks: bytes, most: int = 1000):
    """What `_receive` makes of `chunks` written to a pipe that is then closed."""
    r, w = os.pipe()
    try:
        for c in chunks:
            os.write(w, c)
        os.close(w)
        w = None
        return _receive(r, 5.0, most)
    finally:
        os.close(r)
        if w is not None:
            os.close(w)


def test_a_result_cut_short_or_declaring_more_than_the_budget_is_no_result():
    head = struct.pack("<3Q", 2, 10, 100)  # two parts: 10 and 100 bytes
    assert [bytes(p) for p in _received(head, b"p" * 10, b"b" * 100)] == [b"p" * 10, b"b" * 100]
    assert not _received(head, b"p" * 10, b"b" * 50)  # the child died while writing
    assert not _received(head[:12])
    assert not _received()
    assert _received(head, most=109) == []  # more than the child's memory budget: not a result of ours
    assert _received(struct.pack("<Q", 0)) == []
    r, w = os.pipe()
    os.write(w, head)
    try:
        assert _receive(r, 0.2, 1000) is None  # the rest never comes: the timeout
    finally:
        os.close(r)
        os.close(w)


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
