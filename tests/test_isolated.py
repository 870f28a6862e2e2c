"""A parsing library run in a child process (a fresh interpreter: vehid_cli/core/isolated.py, issues 22 and 26): its
result comes back, and a crash, a hang, a memory blow-up or an exception of the library becomes `Damaged` in the
parent, which lives on and prints nothing of the child's."""

from __future__ import annotations

import os
import pickle
import signal
import struct

import numpy as np
import pytest

from vehid_cli.core.errors import InputError
from vehid_cli.core.errors import clip as quoted
from vehid_cli.core.isolated import Damaged, _framed, _receive, in_child


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


def _received(*chunks: bytes, most: int = 1 << 20):
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


def _loaded(got):
    data, buffers = got
    return pickle.loads(data, buffers=buffers)


def test_a_result_cut_short_or_declaring_more_than_the_budget_is_no_result():
    whole = b"".join(bytes(p) for p in _framed(("ok", [np.arange(5.0), np.arange(3, dtype=np.int8), "x"])))
    out = _loaded(_received(whole))
    np.testing.assert_array_equal(out[1][0], np.arange(5.0))
    np.testing.assert_array_equal(out[1][1], [0, 1, 2])
    for cut in (0, 7, 16, 24, len(whole) - 1):  # the child died while writing: in the header, the pickle, a buffer
        assert _received(whole[:cut]) == ()
    assert _received(whole, most=len(whole) - 100) == ()  # more than the child's memory budget: not a result of ours
    assert _received(struct.pack("<2Q", 2**40, 10)) == ()
    assert _received(struct.pack("<2Q", 0, 0)) == ()
    r, w = os.pipe()
    os.write(w, whole[:30])
    try:
        assert _receive(r, 0.2, 1 << 20) is None  # the rest never comes: the timeout
    finally:
        os.close(r)
        os.close(w)


def _many():
    small = [np.full(k % 5 + 1, k % 100, dtype=np.int8 if k % 2 else float) for k in range(20_000)]
    large = [np.full(4099 + k, k, dtype=np.int8 if k % 2 else float) for k in range(6)]  # odd byte counts, out of band
    return small + large


def test_many_small_and_large_arrays_come_back_equal_aligned_and_writeable():
    out = in_child(_many)
    assert len(out) == 20_006 and all(np.all(a == k % 100) and a.size == k % 5 + 1 for k, a in enumerate(out[:20_000]))
    assert all(np.all(a == k) and a.size == 4099 + k for k, a in enumerate(out[20_000:]))
    assert all(a.flags.aligned and a.flags.writeable for a in out)


def test_bytes_framed_as_a_result_that_do_not_unpickle_are_damaged(monkeypatch):
    import vehid_cli.core.isolated as isolated

    monkeypatch.setattr(isolated, "_receive", lambda fd, timeout, most: (bytearray(b"junk"), []))
    with pytest.raises(Damaged, match="its result cannot be read"):
        in_child(_arrays, 3)


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
