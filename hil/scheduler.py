"""Real-time pacing: absolute deadlines on ``perf_counter_ns``, sleep until shortly before, then spin;
SCHED_FIFO when the process may use it (root), restored afterwards."""

from __future__ import annotations

import os
import time
from typing import Any

SPIN_NS = 300_000  #: stop sleeping this long before a deadline and spin


def set_fifo(pid: int = 0, *, priority: int = 50) -> bool:
    """Put ``pid`` (0: this process) under SCHED_FIFO; False when not permitted."""
    try:
        os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (PermissionError, OSError, AttributeError):
        return False


def set_other(pid: int = 0) -> None:
    """Back to the normal scheduler (best effort)."""
    try:
        os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
    except (PermissionError, OSError, AttributeError, ProcessLookupError):
        pass


class Pacer:
    """Ticks at ``start + (k + 1) * period`` for k = 0, 1, ...

    Parameters
    ----------
    period_ns : int
        Tick period.
    """

    def __init__(self, *, period_ns: int) -> None:
        self.period_ns = int(period_ns)
        self.start_ns = time.perf_counter_ns()
        self.k = 0

    def wait_next(self) -> tuple[int, int]:
        """Wait for the next deadline; returns ``(deadline_ns, now_ns)``, both relative to the start."""
        self.k += 1
        due = self.start_ns + self.k * self.period_ns
        now = time.perf_counter_ns()
        if due - now > SPIN_NS:
            time.sleep((due - now - SPIN_NS) / 1e9)
        now = time.perf_counter_ns()
        while now < due:
            now = time.perf_counter_ns()
        return due - self.start_ns, now - self.start_ns


def pacing_jitter(*, period_ns: int, steps: int, fifo: bool, work: Any = None) -> dict:
    """Jitter of the pacer alone (optionally calling ``work()`` each tick): the real-time baseline."""
    import numpy as np

    on = set_fifo() if fifo else False
    try:
        pacer = Pacer(period_ns=period_ns)
        late = np.empty(steps)
        for k in range(steps):
            due, now = pacer.wait_next()
            late[k] = now - due
            if work is not None:
                work()
    finally:
        if on:
            set_other()
    us = late / 1e3
    return {"p50": float(np.percentile(us, 50)), "p99": float(np.percentile(us, 99)), "max": float(us.max()),
            "sched_fifo": on}
