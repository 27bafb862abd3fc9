"""The Dask client of a campaign: a LocalCluster of process workers, or any scheduler by address.

The same campaign runs on a laptop (``LocalCluster``, one single-threaded process worker per core), a
workstation, or a cluster whose scheduler was started by dask-jobqueue, the Dask Kubernetes operator
or ``dask scheduler`` by hand (``--scheduler tcp://HOST:8786``). On the LocalCluster a run whose worker
dies is rescheduled once (``distributed.scheduler.allowed-failures = 1``); a second death of a worker
under it makes it fail with ``KilledWorker``, which the campaign records. A remote scheduler applies
its own setting (Dask's default: 3). The LocalCluster also turns off Dask's background work that only
a dashboard would show and wakes its processes' event loops seldom (:data:`LOCAL_CONFIG`, :data:`HEARTBEAT_S`),
and its worker processes ignore a Ctrl-C, which the client alone handles (:mod:`.local_worker`); a cluster of
yours keeps its own configuration.
"""

from __future__ import annotations

import ast
import contextlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from types import FrameType
from typing import Any

from gainlink.errors import GainlinkError

log = logging.getLogger(__name__)

ALLOWED_FAILURES = 1
# Dask keeps the last ``low-level-log-length`` messages of each of its batched streams (each under 1 MB: a block's
# task with its pickled runs, ~300 kB for 1,000 runs of the shipped pendulum campaign) and as many transitions and
# events, for its developers' debugging; by default 1,000: the client grew by ~0.6 kB a run up to 1,000 blocks (the
# client's stream to the scheduler, and the LocalCluster's scheduler's to its workers, in this process). A few kept.
RECENT_MESSAGES = 16
CLIENT_CONFIG = {
    "distributed.admin.low-level-log-length": RECENT_MESSAGES,
    # the client's copy of the scheduler's view of the cluster (for its repr and dashboards), by default every 2 s
    "distributed.client.scheduler-info-interval": "10s",
}
# The LocalCluster's own settings. Dask's defaults sample every worker's stack 100 times a second (for a
# dashboard this cluster does not start) and wake every scheduler, worker and nanny 50 times a second to
# time its event loop: measured here, 16 % of a CPU beside a busy single worker; with these, 3 %.
# Each wake-up of an event loop costs on these virtual machines: ~2 ms of CPU with both CPUs busy (a loop that
# does nothing, woken 10 times a second beside two busy processes, took 1.8 % of a CPU, and they lost about that),
# more when a CPU was idle. So what only a dashboard shows is sampled every 10 s, and memory is checked every 5 s
# (a campaign's worker holds ~150-180 MB of a limit of its share of the machine's memory; the nanny still ends one past
# 95 % of it): with these and the wake-ups below (:func:`_fewer_wakeups`), each worker's event loop took 7-9 us of
# CPU a run of a 20,000-run campaign on 2 workers against 7-15 before, the client's 14-15 against 15-27.
LOCAL_CONFIG = {
    "distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
    # worker processes forked from one server that imported what a run needs (:func:`_preload_worker_modules`),
    # instead of each started afresh and importing it again (2-3 CPU-s per worker)
    "distributed.worker.multiprocessing-method": "forkserver",
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "10s",
    "distributed.admin.tick.cycle": "10s",
    "distributed.admin.system-monitor.interval": "10s",
    "distributed.worker.memory.monitor-interval": "5s",
    "distributed.scheduler.active-memory-manager.interval": "10s",
    **CLIENT_CONFIG,
}
#: How often a LocalCluster's worker tells its scheduler it lives (and so looks for missing inputs: Dask ties the
#: two), and the scheduler's checks for timeouts this cluster does not set (idle, no workers) run, in seconds; Dask:
#: every 0.5 s and 0.25 s, not configurable (dask/distributed#3877, #5000). A worker process that dies is seen by its
#: nanny at once, without a heartbeat.
HEARTBEAT_S = 2.0
UNSET_TIMEOUT_CHECKS_S = 5.0

# Without a dashboard the scheduler still serves its HTTP routes (health, metrics), by default on port 8787, and warns
# "Port 8787 is already in use" when another cluster on the host has it: a port of the system's choosing instead,
# on loopback like the rest of the LocalCluster.
SCHEDULER_HTTP = "127.0.0.1:0"
WORKER_SETUP = "gainlink.hil.campaign.local_worker"


def _dask_log_level() -> int:
    """The level of Dask's own logs in the LocalCluster's processes: its errors only when this module logs at DEBUG
    (``gainlink -v``). Every failed run is the campaign's to report (with its reason), and a Ctrl-C stops workers
    in the middle of a run, which then log heartbeats the closing scheduler no longer answers, with tracebacks."""
    return logging.WARNING if log.isEnabledFor(logging.DEBUG) else logging.CRITICAL


def quiet_dask_logs(level: int) -> None:
    """Let Dask's loggers in this process (the client's, and the LocalCluster's scheduler and nannies) pass records
    of ``level`` and above only. Their levels are set one by one: Dask gives several of them their own."""
    import distributed  # noqa: F401 - creates its loggers

    for name in list(logging.root.manager.loggerDict):
        if name.split(".")[0] == "distributed":
            logging.getLogger(name).setLevel(level)


#: imported once by the LocalCluster's fork server, so that every worker forked from it has them
WORKER_MODULES = ("distributed", "numpy", "gainlink.hil.campaign.worker", "gainlink.hil.loop.bridge", WORKER_SETUP)


def _preload_worker_modules() -> None:
    """Have the fork server import :data:`WORKER_MODULES` (with LOCAL_CONFIG set). Dask sets its own list, Dask's
    modules, the first time it asks for the forkserver context; ours replaces it before the server starts (it
    starts with the first worker, and serves this process's later clusters too)."""
    from distributed.utils import get_mp_context

    get_mp_context().set_forkserver_preload(list(WORKER_MODULES))


class ClusterError(GainlinkError, ConnectionError):
    """The Dask scheduler cannot be reached or the cluster cannot start."""


class UnguardedMainError(GainlinkError, RuntimeError):
    """A LocalCluster asked for from a script's top level outside ``if __name__ == "__main__":``.

    Its worker processes start by importing the script again (as ``__mp_main__``, as every ``multiprocessing``
    start method but fork does): unguarded, that import would run the script's top level again in each worker,
    its designs, runs and this very call included, and the workers would fail to start.
    """


def check_main_guard() -> None:
    """Refuse, before any worker starts, a LocalCluster asked for from the unguarded top level of a script.

    The script is the ``__main__`` module a worker would import again (one run as ``python script.py`` or
    ``python -m module``; not an interactive session, a notebook, ``python -c`` or a package's ``__main__``); the
    call is unguarded when the top-level statement running it is not inside an ``if __name__ == "__main__":``
    block.

    Raises
    ------
    UnguardedMainError
        Naming the script, the line and the fix.
    """
    main = sys.modules.get("__main__")
    path = _reimported_main_path(main)
    line = _top_level_line(main)
    if path is None or line is None or _inside_main_guard(path, line):
        return
    raise UnguardedMainError(
        f"campaign: run() is called from the top level of {path} (line {line}), which each worker process of the "
        f'LocalCluster imports again and would run again: put the call under `if __name__ == "__main__":`'
    )


def _reimported_main_path(main: object) -> Path | None:
    """The file of ``__main__`` when a worker process imports it again (multiprocessing.spawn's rule), else None."""
    name = getattr(getattr(main, "__spec__", None), "name", None)
    if name is not None and (name == "__main__" or name.endswith(".__main__")):
        return None  # a package's __main__ is not imported again
    file = getattr(main, "__file__", None)
    if file is None or Path(file).stem == "ipython":
        return None
    return Path(file)


def _top_level_line(main: object) -> int | None:
    """The line of ``__main__``'s top-level code being run now on this thread's stack (None if it is not on it)."""
    namespace = getattr(main, "__dict__", None)
    line, frame = None, sys._getframe(1)
    while frame is not None:
        if frame.f_globals is namespace and frame.f_code.co_name == "<module>":
            line = frame.f_lineno
        frame = frame.f_back
    return line


def _is_main_test(node: ast.expr) -> bool:
    """``__name__ == "__main__"`` (either way round)."""
    if not (isinstance(node, ast.Compare) and len(node.ops) == 1 and isinstance(node.ops[0], ast.Eq)):
        return False
    sides = [node.left, node.comparators[0]]
    names = {s.id for s in sides if isinstance(s, ast.Name)}
    texts = {s.value for s in sides if isinstance(s, ast.Constant)}
    return names == {"__name__"} and texts == {"__main__"}


def _inside_main_guard(path: Path, line: int) -> bool:
    """Whether ``line`` of the script is in the body of an ``if __name__ == "__main__":`` (True when the script
    cannot be read or parsed: nothing is refused on a guess)."""
    try:
        tree = ast.parse(path.read_text("utf-8"), filename=str(path))
    except (OSError, SyntaxError, UnicodeDecodeError, ValueError):
        return True
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and _is_main_test(node.test):
            if node.body[0].lineno <= line <= (node.body[-1].end_lineno or node.body[-1].lineno):
                return True
    return False


@contextlib.contextmanager
def dask_client(
    *, scheduler: str | None = None, workers: int | None = None, timeout: float = 20.0
) -> Iterator[distributed.Client]:  # noqa: F821
    """A connected :class:`distributed.Client` for the length of the block.

    Parameters
    ----------
    scheduler : str, optional
        A scheduler address (``tcp://host:8786``); default: start a LocalCluster.
    workers : int, optional
        LocalCluster process workers (default: the CPUs this process may use).
    timeout : float
        Seconds to wait for the scheduler.
    """
    import dask
    from distributed import Client

    # logged by the client's event loop, in its thread, whenever it runs: in place before the first blocking call
    add_filter_once(logging.getLogger("tornado.application"), DaskSyncCancelRace())
    if scheduler is not None:
        try:
            with dask.config.set(CLIENT_CONFIG):  # read when the client's stream to the scheduler is made
                client = Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        with contextlib.closing(client), _quiet_on_interrupt():
            yield client
        return
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    n = cpus if workers is None else workers
    if n < 1:
        raise ClusterError(f"--workers must be at least 1, not {n}")
    with _local_client(n) as client:
        yield client


@contextlib.contextmanager
def _local_client(n: int) -> Iterator[distributed.Client]:  # noqa: F821
    """:func:`dask_client`'s LocalCluster of ``n`` process workers (:data:`LOCAL_CONFIG`), and its client."""
    import dask
    from distributed import Client, LocalCluster

    with _slower_heartbeats():
        held = _HeldInterrupt()
        with dask.config.set(LOCAL_CONFIG), held:
            _start_fork_server()
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=_dask_log_level(),
                scheduler_kwargs={"dashboard_address": SCHEDULER_HTTP},
                preload=[WORKER_SETUP],  # each worker process ignores SIGINT: the client stops them
                scheduler_sync_interval=10,  # the cluster object's copy of the scheduler's identity (Dask: each 1 s)
            )
        _fewer_wakeups(cluster.scheduler)
        interrupted = False
        try:
            with dask.config.set(CLIENT_CONFIG), contextlib.closing(Client(cluster)) as client, _quiet_on_interrupt():
                held.release()  # a Ctrl-C while the cluster started: now, with the cluster in hand
                yield client
        except KeyboardInterrupt:
            # the nannies then stop workers in the middle of a run, warn that they kill the ones still busy after
            # 4 s, and the closing comms may log errors: the stop the user asked for, not news (the campaign says
            # what it kept); shown with -v
            interrupted = True
            with contextlib.suppress(Exception):  # the interrupt is the news, not what stopping in its middle raised
                _end_workers(cluster)
            with contextlib.suppress(Exception):  # (closed whether or not the workers could be ended first)
                cluster.close()
            raise
        finally:
            if not interrupted:
                cluster.close()


@contextlib.contextmanager
def _slower_heartbeats() -> Iterator[None]:
    """While the block runs, the schedulers of this process ask their workers for a heartbeat every
    :data:`HEARTBEAT_S` at least (Dask's ``heartbeat_interval``, a module function its scheduler calls at each
    heartbeat: no setting changes it). Dask's function is back once the last of this process's LocalClusters (in
    whatever order they close, from whichever thread) has closed."""
    import distributed.scheduler as scheduler

    with _HEARTBEATS["lock"]:
        if _HEARTBEATS["clusters"] == 0:
            original = _HEARTBEATS["dask"] = scheduler.heartbeat_interval
            scheduler.heartbeat_interval = lambda workers: max(original(workers), HEARTBEAT_S)
        _HEARTBEATS["clusters"] += 1
    try:
        yield
    finally:
        with _HEARTBEATS["lock"]:
            _HEARTBEATS["clusters"] -= 1
            if _HEARTBEATS["clusters"] == 0:
                scheduler.heartbeat_interval = _HEARTBEATS["dask"]


_HEARTBEATS: dict[str, Any] = {"lock": threading.Lock(), "clusters": 0, "dask": None}


def _fewer_wakeups(scheduler: Any) -> None:
    """The LocalCluster's scheduler checks the idle and no-worker timeouts every :data:`UNSET_TIMEOUT_CHECKS_S`
    when they are not set (the checks then find nothing to do), not 4 times a second each."""
    timeouts = {"idle-timeout": scheduler.idle_timeout, "no-workers-timeout": scheduler.no_workers_timeout}
    for name, timeout in timeouts.items():
        check = scheduler.periodic_callbacks.get(name)
        if check is not None and timeout is None:
            check.callback_time = 1000 * UNSET_TIMEOUT_CHECKS_S


@contextlib.contextmanager
def _quiet_on_interrupt() -> Iterator[None]:
    """On a Ctrl-C in the block, quiet Dask's logs (:func:`quiet_dask_logs`) before the client closes: a result it
    was fetching when interrupted ends with its key forgotten, which the client logged as an error ("Couldn't gather
    keys") above the line saying what the campaign kept. The interrupt is the news; shown with -v."""
    try:
        yield
    except KeyboardInterrupt:
        quiet_dask_logs(_dask_log_level())
        raise


class DaskSyncCancelRace(logging.Filter):
    """Drops the traceback Dask's event loop logs when a Ctrl-C comes before a blocking call's coroutine started.

    ``distributed.utils.sync`` (2026.8) schedules a ``cancel`` of the call's future on the interrupt; the future is
    made only once the loop thread has run the call, so a ``cancel`` that runs first fails with a ``NameError``
    (``cannot access free variable 'future'``), which tornado logs as "Exception in callback" with its traceback,
    above the line saying what the campaign kept. Nothing was left running (there was no future to cancel). Only that
    record is dropped: a ``NameError`` raised in that function of that module."""

    def filter(self, record: logging.LogRecord) -> bool:
        error = record.exc_info[1] if record.exc_info else None
        if not isinstance(error, NameError) or error.__traceback__ is None:
            return True
        last = error.__traceback__
        while last.tb_next is not None:
            last = last.tb_next
        code = last.tb_frame.f_code
        return not (code.co_name == "cancel" and Path(code.co_filename).parts[-2:] == ("distributed", "utils.py"))


def add_filter_once(logger: logging.Logger, new: logging.Filter) -> None:
    """Add ``new`` to ``logger`` unless a filter of its class is there already."""
    if not any(type(present) is type(new) for present in logger.filters):
        logger.addFilter(new)


def _end_workers(cluster: Any) -> None:
    """End the LocalCluster's worker processes at once (SIGKILL), each nanny told first not to start its worker again.

    After a Ctrl-C their runs' results are not wanted (a block counts once its file is renamed into place, and a file
    being written is a temporary one), and a nanny's own stop asks its worker to close, then waits 4 s for a worker
    busy in a run (a block's C loop cannot be interrupted) before it kills it: a Ctrl-C took 5 s to return."""

    async def end() -> None:
        for nanny in list(cluster.workers.values()):
            pid = nanny.pid
            nanny.close_gracefully(reason="gainlink-interrupted")  # its worker's exit closes it, not a restart
            if pid:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)

    cluster.sync(end)


class _HeldInterrupt:
    """Holds a Ctrl-C that comes while the block runs (in the main thread, where Python's handler or the CLI's is
    in place), for :meth:`release` to raise once the cluster is in hand.

    Interrupted in its start (its workers still ``Status.init``), a LocalCluster can be closed by nobody: the
    constructor never returned it, and Dask's own ``atexit`` closing then failed on an assertion with a traceback.
    A start takes a few seconds; the interrupt waits for it.
    """

    def __init__(self) -> None:
        self._previous: Any = None
        self._frames: list[FrameType | None] = []

    def __enter__(self) -> _HeldInterrupt:
        if threading.current_thread() is threading.main_thread() and callable(signal.getsignal(signal.SIGINT)):
            self._previous = signal.signal(signal.SIGINT, lambda signum, frame: self._frames.append(frame))
        return self

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)

    def release(self) -> None:
        """Raise the held interrupt, through the handler that was in place (Python's raises KeyboardInterrupt)."""
        if self._frames:
            frame, self._frames = self._frames[-1], []
            self._previous(signal.SIGINT, frame)


def _start_fork_server() -> None:
    """Start the fork server the LocalCluster's workers come from, from this thread, with SIGINT blocked.

    It ignores SIGINT only once it has imported :data:`WORKER_MODULES`; a Ctrl-C during those imports (a second or
    more on a busy machine) printed their traceback from the server and stopped the workers' start. A blocked signal
    stays blocked across its exec (as ``multiprocessing.resource_tracker`` starts its own server); the workers
    forked from it unblock it once they ignore it (:mod:`.local_worker`).
    """
    from multiprocessing import forkserver, resource_tracker

    _preload_worker_modules()
    # the server starts the resource tracker first, which blocks SIGINT around its own start and then unblocks it
    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        forkserver.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)
