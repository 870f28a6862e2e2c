"""What the machine a benchmark ran on is: its CPU model beside the host and architecture, so that figures taken on
different VMs (an AMD EPYC and an Intel Xeon ran the same code 1.3-1.5x apart, RESULTS.md's ninth pass) are not read
as a change of the code."""

from __future__ import annotations

import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo), else what the platform says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def host() -> str:
    """'node machine (cpu model)' for a benchmark's header line."""
    return f"{platform.node()} {platform.machine()} ({cpu_model()})"
