"""Scheduling of the bridge and its controller peer: real-time pacing (absolute deadlines on
``perf_counter_ns``, sleep until shortly before, then spin), SCHED_FIFO and a 0 us CPU wake-up
latency request (PM QoS) when the process may use them (root), and CPU affinity — all restored
afterwards.

Affinity matters most in lockstep, where exactly one side runs at a time: on one shared CPU each
hand-over is a local wake-up (a context switch), while on two CPUs every sample costs two
cross-CPU wake-ups of an idle core, which in a virtual machine means waking a halted vCPU
(tens of microseconds each). Busy polling is the opposite case: two spinning peers need two CPUs.
"""

from __future__ import annotations

import gc
import os
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, nullcontext
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


AFFINITIES = ("auto", "shared", "separate", "none")


def resolve_affinity(setting: str, *, mode: str, busy_poll: bool, cpus: Sequence[int]) -> str:
    """The placement ``setting`` stands for: ``auto`` is ``shared`` for a lockstep run without busy
    polling, ``separate`` for busy polling on two or more CPUs, else ``none``."""
    if setting == "auto":
        if busy_poll:
            setting = "separate"
        elif mode == "lockstep":
            setting = "shared"
        else:
            setting = "none"
    if setting == "separate" and len(cpus) < 2:
        return "none"
    return setting


class Placement:
    """Pins this process and the peer process for the length of a run, then restores this process.

    Parameters
    ----------
    setting : str
        One of :data:`AFFINITIES` after :func:`resolve_affinity`: ``shared`` puts both on the
        highest allowed CPU, ``separate`` puts the bridge on the highest and the peer on the next
        one, ``none`` leaves both to the kernel.
    peer_pid : int or None
        The controller process (not restored: it ends with the run).
    """

    def __init__(self, setting: str, *, peer_pid: int | None) -> None:
        self.setting = setting
        self.peer_pid = peer_pid
        self._saved: set[int] | None = None
        self.bridge_cpus: list[int] | None = None
        self.peer_cpus: list[int] | None = None

    def __enter__(self) -> Placement:
        if self.setting == "none" or not hasattr(os, "sched_setaffinity"):
            return self
        allowed = sorted(os.sched_getaffinity(0))
        mine = allowed[-1]
        peer = mine if self.setting == "shared" else allowed[-2]
        try:
            self._saved = set(allowed)
            os.sched_setaffinity(0, {mine})
            self.bridge_cpus = [mine]
            if self.peer_pid is not None:
                os.sched_setaffinity(self.peer_pid, {peer})
                self.peer_cpus = [peer]
        except OSError:  # a peer that already exited, or a CPU taken away by a cgroup: run unpinned
            self.__exit__()
            self.setting, self.bridge_cpus, self.peer_cpus = "none", None, None
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._saved is not None:
            try:
                os.sched_setaffinity(0, self._saved)
            except OSError:
                pass
            self._saved = None

    def describe(self) -> dict:
        """For the report: the placement used and the CPUs of each side (``None``: not pinned)."""
        return {"placement": self.setting, "bridge_cpus": self.bridge_cpus, "controller_cpus": self.peer_cpus}


CPU_DMA_LATENCY = "/dev/cpu_dma_latency"


@contextmanager
def cpu_latency_qos(path: str = CPU_DMA_LATENCY) -> Iterator[bool]:
    """Hold the kernel's CPU wake-up latency request at 0 us for the block (PM QoS, as cyclictest does):
    idle CPUs poll instead of halting, so a wake-up does not wait for a halted (virtual) CPU to come
    back. Yields False when the request cannot be made (not root, no such device)."""
    try:
        fd = os.open(path, os.O_WRONLY)
    except OSError:
        yield False
        return
    try:
        os.write(fd, (0).to_bytes(4, "little", signed=True))
        yield True
    finally:
        os.close(fd)  # closing the file withdraws the request


@contextmanager
def gc_paused() -> Iterator[None]:
    """No cyclic garbage collection inside the block: the HIL loop makes no reference cycles, and a
    collection in the middle of it is a stall of milliseconds."""
    was_on = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_on:
            gc.enable()


OVERRUN_POLICIES = ("skip", "catch_up")


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

    def wait_next(self, *, skip: bool = False) -> tuple[int, int, int]:
        """Wait for the next tick; returns ``(tick, deadline_ns, now_ns)``, times relative to the start.

        ``tick`` counts from 0. After an overrun (woken a whole period or more after the deadline),
        ``skip`` moves on to the latest tick already due, as a real-time executive does, so ``tick``
        jumps by the ticks missed; without it the missed ticks follow back to back (catch up).
        """
        due = self.start_ns + (self.k + 1) * self.period_ns
        now = time.perf_counter_ns()
        if due - now > SPIN_NS:
            time.sleep((due - now - SPIN_NS) / 1e9)
        now = time.perf_counter_ns()
        while now < due:
            now = time.perf_counter_ns()
        if skip and now - due >= self.period_ns:
            self.k += (now - due) // self.period_ns
            due = self.start_ns + (self.k + 1) * self.period_ns
        tick = self.k
        self.k += 1
        return tick, due - self.start_ns, now - self.start_ns


def next_tick(
    pacer: Pacer, k: int, *, steps: int, skip: bool, hold: Callable[[int, int], None]
) -> tuple[int, int, int]:
    """Wait for ``pacer``'s next tick from step ``k``: ``(step to run, its deadline, when woken)``, times relative to
    the pacer's start; the step is ``steps`` or more when the run is over.

    Ticks that passed while the loop was stalled (an overrun, with ``skip``) are held steps: ``hold(j, due_j)``
    runs each (``j < steps``, ``due_j`` its deadline) before the step returned; their count is the step's distance
    from ``k``.
    """
    tick, due, woke = pacer.wait_next(skip=skip)
    for j in range(k, min(tick, steps)):
        hold(j, due - (tick - j) * pacer.period_ns)
    return max(k, min(tick, steps)), due, woke


def pacing_jitter(
    *, period_ns: int, steps: int, fifo: bool, work: Any = None, skip: bool = True, qos: bool = True
) -> dict:
    """Jitter of the pacer alone (optionally calling ``work()`` each tick): the real-time baseline.

    Jitter is measured on the ticks that ran; ``overruns`` counts the ticks skipped (``skip``)."""
    import numpy as np

    on = set_fifo() if fifo else False
    try:
        with gc_paused(), cpu_latency_qos() if qos else nullcontext(False) as qos_on:
            pacer = Pacer(period_ns=period_ns)
            late = np.full(steps, np.nan)
            k = 0
            while k < steps:
                tick, due, now = pacer.wait_next(skip=skip)
                if tick >= steps:
                    break
                late[tick] = now - due
                k = tick + 1
                if work is not None:
                    work()
    finally:
        if on:
            set_other()
    ran = late[np.isfinite(late)] / 1e3
    return {
        "p50": float(np.percentile(ran, 50)),
        "p99": float(np.percentile(ran, 99)),
        "max": float(ran.max()),
        "overruns": int(steps - ran.size),
        "sched_fifo": on,
        "pm_qos": qos_on,
    }
