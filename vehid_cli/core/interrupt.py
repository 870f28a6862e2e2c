"""Stopping a command cleanly on SIGINT (Ctrl-C) or SIGTERM (kill, a job scheduler's stop): the signal becomes an
exception in the main thread, the command's context managers stop workers and remove unfinished writes, and the
process then ends by the same signal, as shells and job schedulers expect (status 128 + signal)."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM, raised in the main thread so that a campaign stops cleanly."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def interruptible(resume_hint: Callable[[], str], say: Callable[[str], None]) -> Iterator[None]:
    """A context for identify and sweep: SIGINT and SIGTERM stop the command cleanly (workers stopped, unfinished
    writes removed, finished runs kept in the checkpoint). It says what `resume_hint()` returns through `say`, then
    ends the process by the same signal. SIGKILL cannot be caught; the checkpoint covers it too."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise Interrupted(signum)

    inherited = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    # a signal the process was started ignoring (SIGINT of a background job) stays ignored
    previous = {s: signal.signal(s, handler) for s, h in inherited.items() if h is not signal.SIG_IGN}
    try:
        yield
    except Interrupted as exc:
        for s, h in previous.items():
            signal.signal(s, h)
        say(f"interrupted by {signal.Signals(exc.signum).name}: {resume_hint()}")
        sys.stdout.flush()
        sys.stderr.flush()
        signal.signal(exc.signum, signal.SIG_DFL)
        os.kill(os.getpid(), exc.signum)
        raise
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
