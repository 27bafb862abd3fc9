"""A command's processes, as a test that interrupts it sees them (Linux /proc)."""

from __future__ import annotations

import contextlib
import os


def children(pid: int) -> set[int]:
    """The child processes of ``pid``, of every thread of it (a Dask nanny starts its worker from a thread)."""
    found: set[int] = set()
    with contextlib.suppress(OSError):
        for task in os.listdir(f"/proc/{pid}/task"):
            with contextlib.suppress(OSError), open(f"/proc/{pid}/task/{task}/children") as f:
                found.update(int(c) for c in f.read().split())
    return found


def children_running(pid: int, program: bytes) -> set[int]:
    """The child processes of ``pid`` whose command line contains ``program``."""
    found = set()
    for child in children(pid):
        with contextlib.suppress(OSError), open(f"/proc/{child}/cmdline", "rb") as f:
            if program in f.read():
                found.add(child)
    return found


def group_alive(pgid: int) -> bool:
    """Whether any process of the process group ``pgid`` is still running."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True
