"""What runs on a Dask worker: one campaign run as a pure function of (artifact bytes, scenario, seed).

:func:`execute` is one run; a Dask task is :func:`execute_block`, a list of runs: a HIL run alone, SIL runs in blocks
stepped together (:mod:`gainlink.hil.loop.block`: a task per run cost more than the run's tenth in Dask's bookkeeping,
and a run stepped alone costs numpy's per-call price at every step). Its inputs travel as bytes (the artifact's
canonical JSON, FMU archives by sha256); the worker writes each once into a host-local cache named by sha256, builds the
firmware once per artifact (the firmware build cache is keyed by the artifact's sha256 and serialised by a file lock
between the processes of a host) and remembers the result (of the :data:`WORKER_CACHE` artifacts it used last), so the
second run of an artifact pays nothing for it. At a task's end with no other task ready to run (the last block of a
campaign, :func:`next_task_waiting`) it hands back to the system what the task's arrays left free in its allocators
(:func:`hand_back_memory`), so a worker's memory does not keep its largest block's peak.

A HIL run takes a *bus slot* first: a file lock no other process on the host holds. The slot gives the
run its own udp_multicast group and port (or its own CAN id base on a shared SocketCAN bus, or its own
MAVLink UDP port) and one CPU for the bridge and its controller, so parallel HIL runs on one host never
hear each other or fight for a core.

A run-time fault the run itself reports (a plant that fails, a peer that dies: ``complete = False``)
is a result. A :class:`~gainlink.errors.GainlinkError` before or around the run is recorded as the run's
error. Anything else propagates, so Dask retries the run (on another worker when this one died).
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import fcntl
import itertools
import json
import logging
import os
import pickle
import socket
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import GainlinkError, TransportError
from gainlink.fileio import atomic_write_bytes
from gainlink.shipping.artifact import Artifact, from_dict

from ..loop.scenario import DRAWN, parse_scenario
from ..paths import cache_dir
from ..plants.fmu import reused_instances
from .block_columns import BlockRuns
from .block_file import encode_block, encode_runs, with_inputs, write_block
from .config import Criteria, path_steps
from .criteria import measure, measure_block
from .judged import judge_part
from .plan import DescribedRuns, MadeRuns
from .store import block_report_part

MAX_TRACE_POINTS = 600
MAX_BUS_SLOTS = 64
MULTICAST_GROUP = "239.74.164.{}"  # slot k uses host {k + 1} of this /24
MULTICAST_PORT0 = 43200
MAVLINK_PORT0 = 14600
CAN_ID_STRIDE = 0x40

log = logging.getLogger(__name__)

#: Entries each of the worker's caches keeps (artifacts, their libraries and executables, FMU files), the least
#: recently used dropped past it: a campaign's tasks use a few (one per grid point of its design: the shipped ones 2
#: or 3), but a campaign that draws the design itself (a ``spec.*`` draw axis) has an artifact per run, and a worker
#: lives through many campaigns. A parsed artifact holds ~20 kB (measured: 40 artifacts, 0.8 MB); a miss costs a parse
#: and a look-up in the firmware build cache, not a build.
WORKER_CACHE = 64
#: Runs stepped in lockstep at most (a task of more steps them in parts, :func:`lockstep_parts`): a block's state of
#: ~1,000 pendulum runs fits the core's cache; past it the runs' own CPU a run-step grows (~15 % at 2,500).
LOCKSTEP_RUNS = 1000
_ARTIFACTS: dict[str, tuple[Artifact, Path]] = {}
_LIBRARIES: dict[str, Path] = {}
_EXECUTABLES: dict[tuple[str, str], Path] = {}
_FMUS: dict[str, Path] = {}
# glibc's: hands the free pages of the heap back to the system (None on other C libraries)
_MALLOC_TRIM = getattr(ctypes.CDLL(None), "malloc_trim", None) if sys.platform.startswith("linux") else None


def _local(sub: str) -> Path:
    return cache_dir(f"campaign/{sub}")


def _write_once(path: Path, data: bytes) -> Path:
    if not path.is_file():
        atomic_write_bytes(path, data)
    return path


def _kept(cache: dict, key: Any, make: Callable[[], Any]) -> Any:
    """``cache[key]``, made by ``make()`` when missing; past :data:`WORKER_CACHE` entries the least recently used is
    dropped (a dict keeps its insertion order: a hit moves its entry last)."""
    if key in cache:
        cache[key] = value = cache.pop(key)
        return value
    value = cache[key] = make()
    while len(cache) > WORKER_CACHE:
        del cache[next(iter(cache))]
    return value


def artifact_from_bytes(data: bytes) -> tuple[Artifact, Path]:
    """The artifact of canonical JSON bytes (validated once while the worker keeps it) and its host-local file."""
    doc = json.loads(data)
    sha = doc.get("sha256", "") if isinstance(doc, dict) else ""
    if sha in _ARTIFACTS:
        return _kept(_ARTIFACTS, sha, lambda: None)
    art = from_dict(doc)
    return _kept(_ARTIFACTS, art.sha256, lambda: (art, _write_once(_local("artifacts") / f"{art.sha256}.json", data)))


def _fmu_path(ref: str, blobs: dict[str, bytes]) -> Path:
    sha = ref.removeprefix("sha256:")
    if sha not in _FMUS and sha not in blobs:
        raise GainlinkError(f"campaign run names FMU {sha[:12]}... but it did not travel with the run")
    return _kept(_FMUS, sha, lambda: _write_once(_local("fmus") / f"{sha}.fmu", blobs[sha]))


def _library(artifact: Artifact) -> Path:
    """The host library the law's SIL runs step (``Law.native``: built and cached by sha256 on first use), kept while
    the worker uses the artifact so the next run of it pays nothing for it."""

    def find() -> Path:
        from gainlink.laws import law_of

        return Path(law_of(artifact).native(artifact).describe["library"])

    return _kept(_LIBRARIES, artifact.sha256, find)


def _executable(artifact: Artifact, transport: dict) -> Path:
    kind = transport.get("kind", "can")

    def build() -> Path:
        if kind == "mavlink":
            from gainlink.firmware.mavlink_app import mavlink_executable

            return mavlink_executable(artifact)
        from ..links.can_firmware import firmware_can_executable

        return firmware_can_executable(artifact)

    return _kept(_EXECUTABLES, (artifact.sha256, kind), build)


@contextlib.contextmanager
def bus_slot() -> Iterator[int]:
    """A slot number no other process on this host holds until the block ends (a file lock)."""
    folder = Path("/tmp") / f"gainlink-bus-slots-{os.getuid()}"
    folder.mkdir(exist_ok=True)
    for k in range(MAX_BUS_SLOTS):
        fh = open(folder / f"{k}.lock", "w")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.close()
            continue
        try:
            yield k
        finally:
            fh.close()
        return
    raise TransportError(f"no free bus slot: {MAX_BUS_SLOTS} HIL runs already share this host")


def isolate_transport(transport: dict, slot: int) -> dict:
    """The transport table of a run in bus slot ``slot``: its own group and port, or CAN id base, or UDP port."""
    t = dict(transport)
    if t.get("kind") == "mavlink":
        if "url" in t or "controller_url" in t:
            raise TransportError(
                "campaign: a MAVLink transport with explicit urls cannot be given a port per run; "
                "give port (the campaign offsets it per run)"
            )
        t["port"] = MAVLINK_PORT0 + 2 * slot
    elif t.get("interface") == "udp_multicast":
        t["channel"] = MULTICAST_GROUP.format(slot + 1)
        t["port"] = MULTICAST_PORT0 + slot
    else:  # one shared bus (socketcan, vcan0): own identifiers
        base = t.get("base_id", 0x100)
        base = int(base, 0) if isinstance(base, str) else int(base)
        t["base_id"] = base + CAN_ID_STRIDE * slot
        if t["base_id"] + CAN_ID_STRIDE > 0x7FF:
            raise TransportError(f"campaign: bus slot {slot} leaves no 11-bit CAN identifiers above base_id {base:#x}")
    return t


@contextlib.contextmanager
def _one_cpu(slot: int) -> Iterator[None]:
    """Confine this process (and so the bridge's shared placement) to one CPU chosen by the slot."""
    if not hasattr(os, "sched_setaffinity"):
        yield
        return
    saved = os.sched_getaffinity(0)
    cpus = sorted(saved)
    os.sched_setaffinity(0, {cpus[slot % len(cpus)]})
    try:
        yield
    finally:
        os.sched_setaffinity(0, saved)


def _scenario(scenario: dict, *, artifact_path: Path, seed: int, blobs: dict, kind: str):
    data = json.loads(json.dumps(scenario))
    data["artifact"] = str(artifact_path)
    data["seed"] = int(seed)
    plant = data.get("plant", {})
    if plant.get("kind") == "fmu" and str(plant.get("path", "")).startswith("sha256:"):
        plant["path"] = str(_fmu_path(plant["path"], blobs))
    if kind == "sil":  # in process: no link, whatever the scenario's table says
        data["transport"] = {}
    return parse_scenario(data)


def downsampled_trace(trace: Any) -> dict[str, np.ndarray]:
    """The run's t, y, u, r at no more than :data:`MAX_TRACE_POINTS` evenly spaced samples (first and last
    kept), as the block file stores them (:func:`~.block_layout.encode_trace`: float32 arrays)."""
    return downsampled_traces([trace])[0]


def downsampled_traces(traces: list) -> list[dict[str, np.ndarray]]:
    """:func:`downsampled_trace` of each of ``traces``, taken for the runs of one length at once: one gather and one
    float32 conversion of their ``(runs, steps, width)`` arrays, each run's arrays a contiguous row of them."""
    return _downsampled(traces)[0]  # type: ignore[return-value]  (every run kept: no None)


def _downsampled(
    traces: list, kept: Sequence[bool] | None = None
) -> tuple[list[dict[str, np.ndarray] | None], dict[str, np.ndarray] | None]:
    """:func:`downsampled_traces` of the runs ``kept`` says (None: every run; the others' None, not gathered), and
    when every run is kept and of one length their arrays as the gather made them (the rows the runs' arrays are:
    ``t`` (runs, N), ``y``, ``u``, ``r`` (runs, N, width)), else None."""
    from ..loop.block_metrics import stacked

    out: list[dict | None] = [None] * len(traces)
    lengths: dict[int, list[int]] = {}
    for i, tr in enumerate(traces):
        if kept is None or kept[i]:
            lengths.setdefault(int(tr.t.size), []).append(i)
    cols: dict[str, np.ndarray] = {}
    for N, members in lengths.items():
        idx = np.unique(np.linspace(0, N - 1, min(N, MAX_TRACE_POINTS)).round().astype(int)) if N else np.zeros(0, int)
        cols = {k: _gathered(stacked([getattr(traces[i], k) for i in members]), idx) for k in "tyur"}
        for j, i in enumerate(members):  # each row float32, contiguous and shaped as encode_trace makes it
            out[i] = {"t": cols["t"][j], "y": cols["y"][j], "u": cols["u"][j], "r": cols["r"][j]}
    whole = len(lengths) == 1 and (kept is None or all(kept))
    return out, cols if whole else None  # type: ignore[return-value]


def _gathered(A: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``A[:, idx]`` (runs, steps, ...) as float32, C-ordered (each run's rows contiguous: ``A[:, idx]`` lays the
    gathered axis out first, and its float32 copy keeps that order, ~6x slower than ``np.take``); one row gathered for
    all when the runs share one array (the plan's times and references: a view whose runs' stride is 0)."""
    if A.shape[0] and A.strides[0] == 0:
        return np.broadcast_to(A[0].take(idx, axis=0).astype(np.float32), (A.shape[0], idx.size, *A.shape[2:]))
    return A.take(idx, axis=1).astype(np.float32)


def run_point(kind: str, artifact: Artifact, scenario: Any) -> Any:
    """Run one parsed scenario through the one dispatcher (:func:`~gainlink.hil.loop.bridge.run_scenario`): SIL in
    process (its transport table is empty), HIL over its link in its own bus slot."""
    from ..loop.bridge import run_scenario

    if kind == "sil":
        library = _library(artifact) if scenario.controller == "firmware" else None
        return run_scenario(scenario, artifact=artifact, library=library)
    with bus_slot() as slot, _one_cpu(slot):
        held = time.time()
        transport = isolate_transport(scenario.transport, slot)
        firmware = _executable(artifact, transport) if scenario.controller == "firmware" else None
        scenario = dataclasses.replace(scenario, transport=transport, firmware=firmware)
        result = run_scenario(scenario, artifact=artifact)
        # when this run held its slot (its bus): runs whose holds overlap never share a bus
        result.info["transport"]["bus_slot"] = {"slot": slot, "start": held, "stop": time.time()}
        return result


def execute(kind: str, artifact_json: bytes, scenario: dict, seed: int, blobs: dict | None = None) -> dict:
    """One campaign run: a JSON-able record plus its downsampled traces (``trace``:
    :func:`~.block_layout.encode_trace`'s arrays).

    Parameters
    ----------
    kind : {"sil", "hil"}
    artifact_json : bytes
        The artifact's canonical JSON.
    scenario : dict
        The run's scenario table (without ``artifact``; an FMU plant's ``path`` is ``sha256:<hex>``).
    seed : int
        The run's seed (noise, random faults).
    blobs : dict, optional
        FMU archives by sha256.
    """
    where = {"host": socket.gethostname(), "pid": os.getpid(), "start": time.time()}
    cpu0 = time.thread_time()
    try:
        artifact, path = artifact_from_bytes(artifact_json)
        sc = _scenario(scenario, artifact_path=path, seed=seed, blobs=blobs or {}, kind=kind)
        with reused_instances():  # an FMU plant's instance serves this worker's next run of the FMU
            result = run_point(kind, artifact, sc)
    except GainlinkError as exc:
        return {"status": "error", "reason": str(exc), "worker": _stopped(where, cpu0)}
    record = _record(result, artifact)
    del result  # let go inside the run's time, as a block's runs are (:func:`_run_block`)
    return record | {"worker": _stopped(where, cpu0)}


def _record(result: Any, artifact: Artifact, *, measures: dict | None = None, trace: dict | None = None) -> dict:
    """A finished run's record (without ``worker``): status, metrics, measures, link, downsampled traces
    (``measures``, ``trace``: a block's, taken for its runs together by :func:`~.criteria.measure_block` and
    :func:`downsampled_traces`; by default the run's own)."""
    return _done(
        result.complete,
        result.reason,
        result.metrics,
        measure(result, artifact) if measures is None else measures,
        result.info["transport"],
        downsampled_trace(result.trace) if trace is None else trace,
    )


def _done(complete: bool, reason: str | None, metrics: dict, measures: dict, link: dict, trace: dict | None) -> dict:
    """A finished run's record (without ``worker``) from its parts."""
    return {"status": "done", "complete": complete, "reason": reason, "metrics": metrics, "measures": measures,
            "link": link, "trace": trace}  # fmt: skip


def _stopped(where: dict, cpu0: float) -> dict:
    """``where`` with the run's end: ``stop`` (wall clock) and ``cpu_s``, the CPU time of the thread that ran it
    (the bridge's, not a HIL run's firmware process)."""
    return where | {"stop": time.time(), "cpu_s": time.thread_time() - cpu0}


def execute_block(
    kind: str,
    artifacts: dict[str, bytes],
    runs: Sequence,
    blobs: dict | None = None,
    *,
    ids: list[str],
    campaign: str,
    folder: tuple[str, tuple[int, int]] | None = None,
    kept: Sequence[bool] | None = None,
    criteria: Criteria | None = None,
) -> bytes | dict:
    """A campaign task: the runs of :func:`batch_records` (run ``ids[i]`` is ``runs[i]``) as the block's Parquet
    file for the campaign folder (:func:`~.block_file.encode_block`), the traces of the runs ``kept`` says (every run's
    when None; the others' null). Given the campaign's ``criteria``, the block's runs judged too
    (:func:`~.judged.judge_part`, the answer's ``judged``): the client files their verdicts in as it stores the block,
    instead of judging them itself after the last run.

    ``folder``: the campaign's ``blocks`` folder and its :func:`~.block_file.folder_key` as the client saw them. When
    this worker sees that folder (a LocalCluster, a shared file system), it writes the file there itself and returns a
    few numbers (:func:`~.block_file.write_block`: the file's name, the runs, the errors' reasons); else it returns the
    file's bytes and the client writes them.
    """
    from ..loop.scheduler import gc_paused

    with gc_paused():  # see execute_packed
        try:
            return _block_answer(
                kind, artifacts, runs, blobs, ids=ids, campaign=campaign, folder=folder, kept=kept, criteria=criteria
            )
        finally:  # the block's arrays and records are freed by now
            if not next_task_waiting():
                hand_back_memory()


def next_task_waiting() -> bool:
    """Whether this process is a Dask worker with another task ready to run, which will reuse the pages the task
    ending leaves free: a worker of a campaign under way hands its memory back after its last block, not after each.
    Handed back after each block, the next one took every page again from the system (measured: 6,000-7,000 page
    faults and 35-70 µs of kernel CPU a run of a 834-run block, against 0-1,400 and 0-15 kept). A task ready when a
    block ended that Dask then gives another worker leaves this one holding a block's pages until its next block ends.
    ``False`` outside a Dask worker's task (its memory handed back after each block, as before)."""
    try:
        from distributed import get_worker

        return len(get_worker().state.ready) > 0
    except (ImportError, ValueError, AttributeError):  # ValueError: not in a worker's task
        return False


def _block_answer(
    kind: str,
    artifacts: dict,
    runs: list,
    blobs: dict | None,
    *,
    ids: list[str],
    campaign: str,
    folder: Any,
    kept: Sequence[bool] | None,
    criteria: Criteria | None = None,
) -> bytes | dict:
    """:func:`execute_block`'s answer: its block file written into ``folder`` (a few numbers) or its bytes, with the
    runs judged against ``criteria`` when given (a dict then: the bytes its ``data``)."""
    task = _task_records(kind, artifacts, runs, blobs, kept)
    if task and all(type(r) is _Block for r in task):  # only blocks' runs: a column at a time, no record dict a run
        data = encode_runs(ids, _block_runs(kind, runs, task), campaign=campaign)
        errors: list = []
    else:
        records = [with_inputs(r, run, kind=kind) for r, run in zip(_materialized(task), runs)]
        data = encode_block(ids, records, campaign=campaign)
        errors = [[i, r.get("reason")] for i, r in enumerate(records) if r["status"] == "error"]
    judged = {} if criteria is None else _judged(data, criteria)
    if folder is not None:
        answer = write_block(folder[0], folder[1], ids, data, errors)
        if answer is not None:
            return answer | judged
    if judged:
        return {"data": data.to_pybytes()} | judged
    return data.to_pybytes()  # to the client, which writes it


def _judged(data: Any, criteria: Criteria) -> dict:
    """``{"judged": ...}``: the runs of block file ``data`` judged (:func:`~.judged.judge_part`); empty (the client
    judges them) when that fails, said in the log. Judged from the file's bytes, not from the columns before they were
    encoded (~5-10 ms of decoding a 2,500-run block): what is judged is then what the store will read."""
    try:
        return {"judged": judge_part(block_report_part(data), criteria)}
    except Exception as exc:  # the runs are stored either way: their verdicts are made on the client instead
        log.warning(
            "block of %d bytes not judged on the worker (%s: %s): judged on the client",
            len(data),
            type(exc).__name__,
            exc,
        )
        return {}


def hand_back_memory() -> None:
    """Give the system back the memory a finished task's arrays left free in this process's allocators.

    A block's arrays and its Parquet file are freed when the task ends, but the allocators keep the pages for later:
    Arrow's pool (mimalloc) those of the file, glibc's heap those of the arrays. Nothing leaks (a worker's memory
    stays below what its largest block needed), but without this a worker that once ran a large block holds that
    block's peak for the rest of its life (measured: a 200-run block of 4 s pendulum runs left 68 MB held, 49 of them
    in Arrow's pool). ``MALLOC_ARENA_MAX`` would not help: a worker's tasks run on one thread, in one arena.
    """
    import pyarrow as pa

    pa.default_memory_pool().release_unused()
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


def execute_packed(
    kind: str,
    artifacts: dict[str, bytes],
    packed: bytes,
    blobs: dict | None = None,
    *,
    campaign: str,
    folder: tuple[str, tuple[int, int]] | None = None,
    criteria: Criteria | None = None,
) -> bytes | dict:
    """:func:`execute_block` as the campaign submits it: ``packed`` is ``pickle.dumps((ids, runs, kept))``, ``runs`` as
    :meth:`.plan.PlannedRuns.task` gives them (described, or a list of each run's inputs), ``kept`` whose traces to
    store (None: every run's). One bytes
    argument is what Dask's graph code walks past: a list of runs' scenarios as an argument is walked element by
    element on the client for dependencies (measured: 11,000 calls a block of 500 pendulum runs)."""
    from ..loop.scheduler import gc_paused

    # Without cyclic garbage collection for the whole task: a block's runs, texts and columns are ~10^5 objects in
    # acyclic lists and dicts, and collections in its steps outside the runs (grouping, storing) cost ~50 a worker's
    # 10,002-run campaign (0.3 ms each, a full one 30-60 ms). Paused, the task's garbage is found by the first
    # collection after it (a traceback's cycles, say).
    with gc_paused():
        ids, runs, kept = pickle.loads(packed)
        if isinstance(runs, DescribedRuns):  # made once: grouped, run and recorded from the same runs
            runs = runs.made_runs()
        return execute_block(
            kind, artifacts, runs, blobs, ids=ids, campaign=campaign, folder=folder, kept=kept, criteria=criteria
        )


def batch_records(kind: str, artifacts: dict[str, bytes], runs: Sequence, blobs: dict | None = None) -> list[dict]:
    """A task's campaign runs, their records in order.

    Parameters
    ----------
    kind : {"sil", "hil"}
    artifacts : dict
        The artifacts' canonical JSON by sha256 (each once, however many runs use it).
    runs : sequence of (artifact sha256, scenario, seed)
        As in :func:`execute`: a list, or a :class:`~.plan.DescribedRuns` (a task's runs described by their grid
        points and draws; ``runs[i]`` makes run ``i``'s).
    blobs : dict, optional
        FMU archives by sha256.

    SIL runs of one artifact, controller and length step together as a block (:func:`gainlink.hil.loop.block.run_block`:
    each run's record is the one it gets alone); a run that cannot (a link, faults, a plant that is not vectorised)
    runs alone, and the block says why once (a log line on the worker, ``worker.block`` in its records). A run whose
    plant cannot be built (a drawn number it refuses) is left out of its block and runs alone, recording its error; a
    block that fails otherwise with a :class:`~gainlink.errors.GainlinkError` is run again one run at a time, so one
    bad run costs no other its result. An exception other than a :class:`~gainlink.errors.GainlinkError` ends the task
    (the campaign then runs each of its runs alone, so one bad run costs no other its result).
    """
    if isinstance(runs, DescribedRuns):
        runs = runs.made_runs()
    return _materialized(_task_records(kind, artifacts, runs, blobs))


def _task_records(
    kind: str, artifacts: dict[str, bytes], runs: Sequence, blobs: dict | None, kept: Sequence[bool] | None = None
) -> list:
    """:func:`batch_records`' records, a run of a block given by its :class:`_Block` (its lists, not a dict); a run
    not ``kept`` (None: every run is) without its trace."""
    records: list[dict | _Block | None] = [None] * len(runs)
    if kind == "sil":
        for members in _blocks(artifacts, runs, blobs or {}).values():
            for part in lockstep_parts(members):
                _run_block(part, records, runs, blobs or {}, kept)
    for i, record in enumerate(records):
        if record is None:
            sha, scenario, seed = runs[i]
            records[i] = execute(kind, artifacts[sha], scenario, seed, blobs)
            if kept is not None and not kept[i]:
                records[i]["trace"] = None  # type: ignore[index]
    return records


def lockstep_parts(members: list) -> list[list]:
    """``members`` (the runs of one block key) in as few consecutive parts of at most :data:`LOCKSTEP_RUNS` as hold
    them, of sizes differing by one at most: each part steps in lockstep, and the task's runs make one file."""
    count = -(-len(members) // LOCKSTEP_RUNS)
    bounds = [len(members) * k // count for k in range(count + 1)]
    return [members[a:b] for a, b in itertools.pairwise(bounds)]


@dataclasses.dataclass(frozen=True)
class _Block:
    """The finished runs of a block, as lists: their positions in the task, what their results say (``complete``,
    ``reason``, ``metrics``, ``link``), measures (a run's dict, by :func:`~.criteria.measure_block`), stored traces,
    and the block's share of the worker's time (``worker``). Not the results themselves: their traces hold the
    block's arrays, which the task's next lockstep part (:func:`lockstep_parts`) then steps in again."""

    positions: list[int]
    complete: list
    reason: list
    metrics: list
    link: list
    measures: list
    traces: list
    worker: dict
    stack: dict[str, np.ndarray] | None = None  # the traces as the block's arrays (runs of one length), else None
    metric_trees: list | None = None  # the metrics as column trees by position in the block, when every run is one's

    @staticmethod
    def parts(results: list, *, metrics: bool) -> tuple[list, list, list | None, list]:
        """What a block keeps of its ``results``: ``complete``, ``reason``, ``metrics`` (their dicts, or None when
        ``metrics`` is false: the block's column trees hold them) and ``link``."""
        return ([r.complete for r in results], [r.reason for r in results],
                [r.metrics for r in results] if metrics else None, [r.info["transport"] for r in results])  # fmt: skip

    def metric_rows(self) -> list[dict]:
        """Each run's metrics dict, in the block's order: those it holds, or made from its column trees."""
        if self.metrics is not None:
            return self.metrics
        from ..loop.block_metrics import BlockMetrics

        return BlockMetrics(self.metric_trees, len(self.positions)).rows()  # type: ignore[arg-type]

    def record(self, j: int, metrics: dict) -> dict:
        """The record of the block's ``j``-th run (its metrics ``metrics``), as :func:`execute` gives a run's."""
        record = _done(self.complete[j], self.reason[j], metrics, self.measures[j], self.link[j], self.traces[j])
        return record | {"worker": dict(self.worker)}


def _materialized(task: list) -> list[dict]:
    """A task's records (:func:`_task_records`), each block's run as its record dict."""
    index: dict[tuple[int, int], int] = {}  # (block, position in the task): the run's index in its block
    rows: dict[int, list[dict]] = {}  # each block's runs' metrics dicts
    for block in {id(r): r for r in task if type(r) is _Block}.values():
        index.update(((id(block), i), j) for j, i in enumerate(block.positions))
        rows[id(block)] = block.metric_rows()
    return [r.record(j := index[id(r), i], rows[id(r)][j]) if type(r) is _Block else r for i, r in enumerate(task)]


def _block_runs(kind: str, runs: list, task: list) -> BlockRuns:
    """The task's runs, every one a block's (``task``: :func:`_task_records`), as the lists of
    :func:`~.block_file.encode_runs`, in task order."""
    blocks = list({id(b): b for b in task}.values())
    order = np.argsort(np.concatenate([b.positions for b in blocks]), kind="stable").tolist()
    ordered = order == list(range(len(order)))

    def column(of: Callable[[_Block], list]) -> list:
        values = [v for b in blocks for v in of(b)]
        return values if ordered else [values[k] for k in order]

    trees = _task_trees(blocks)
    trees_of_runs = runs.described.scenario_trees() if isinstance(runs, MadeRuns) else None
    one = len(blocks) == 1 and ordered  # the block's runs are the task's, run for run
    whole = one and blocks[0].stack is not None  # and so are its traces' arrays (every trace kept, of one length)
    return BlockRuns(
        kind=kind,
        inputs=runs,
        complete=column(lambda b: b.complete),
        reason=column(lambda b: b.reason),
        metrics=None if trees is not None else column(_Block.metric_rows),
        measures=column(lambda b: b.measures),
        link=column(lambda b: b.link),
        traces=blocks[0].stack if whole else column(lambda b: b.traces),  # type: ignore[arg-type]
        worker=column(lambda b: [b.worker] * len(b.positions)),
        metric_trees=trees,
        scenario_trees=trees_of_runs,
        input_columns=runs.columns() if trees_of_runs is not None else None,
    )


def _task_trees(blocks: list[_Block]) -> list | None:
    """The blocks' metrics column trees with each run's position in the task (a block's trees hold its runs by their
    position in the block), joined into one (:func:`~..loop.block_metrics.joined`: the task's lockstep parts share a
    structure, and its file's columns are then made from one tree, not a dict a run), or None when a block has none."""
    from ..loop.block_metrics import joined

    if any(b.metric_trees is None for b in blocks):
        return None
    trees = [([b.positions[j] for j in positions], tree) for b in blocks for positions, tree in b.metric_trees]
    if len(trees) == 1:
        return trees
    return [([i for positions, _ in trees for i in positions], joined([(tree, len(pos)) for pos, tree in trees]))]


def _blocks(artifacts: dict[str, bytes], runs: Sequence, blobs: dict) -> dict[tuple, list]:
    """The SIL runs that can step together, by (artifact, controller, steps, the plant but its drawn numbers):
    ``(index, artifact, scenario)``; a run whose inputs are wrong is left out (it runs alone and records its error).
    Runs made from their description (:class:`~.plan.MadeRuns`) go by their grid points (:func:`_described_blocks`);
    runs enumerated are each compared with the last one parsed of its artifact: one that differs from it only in its
    seed and its plant's drawn numbers (:data:`DRAWN`) is that scenario with its own (:func:`_drawn_like`), parsed
    once per block, not once per run."""
    if isinstance(runs, MadeRuns):
        return _described_blocks(artifacts, runs, blobs)
    groups: dict[tuple, list] = {}
    parsed: dict[str, tuple] = {}  # per artifact: (the last table parsed, its parse: artifact, scenario, key)
    files: dict[str, tuple] = {}
    for i, (sha, scenario, seed) in enumerate(runs):
        last = parsed.get(sha)
        sc = _drawn_like(last[0], last[1][1], scenario, seed) if last is not None else None
        if sc is None:
            made = _parsed(artifacts, files, sha, scenario, seed, blobs, i)
            if made is None:
                continue
            last = parsed[sha] = (scenario, made)
            sc = made[1]
        groups.setdefault(last[1][2], []).append((i, last[1][0], sc))
    return groups


def _described_blocks(artifacts: dict[str, bytes], runs: MadeRuns, blobs: dict) -> dict[tuple, list]:
    """:func:`_blocks` of runs made from their description: by grid point, the first run that steps in a block parsed
    and, when every draw axis sets a number of the plant's drawn tables (:func:`_drawn_only`), each other run that
    scenario with its own seed and drawn tables (:func:`_with_drawn`; the tables from the part's columns,
    :func:`_part_tables`, its runs' scenarios not made), compared with nothing; else each run parsed."""
    groups: dict[tuple, list] = {}
    files: dict[str, tuple] = {}
    drawn_only = _drawn_only(runs.described.axes)
    seeds = runs.described.seeds.tolist()
    for part in runs.described.parts:
        tables = _part_tables(runs.described, part) if drawn_only else None
        first = None
        for i in range(part.start, part.stop):
            if first is None:
                sc = None
            elif tables is not None:  # a part's tables: numbers, each run's own
                sc = _like(first[1], seeds[i], tables[i - part.start])
            else:
                drawn = _run_tables(runs[i][1])
                sc = None if drawn is None else _with_drawn(first[1], seeds[i], drawn)
            if sc is not None:
                artifact, key = first[0], first[2]
            else:
                sha, scenario, seed = runs.one(i)
                made = _parsed(artifacts, files, sha, scenario, seed, blobs, i)
                if made is None:
                    continue
                artifact, sc, key = made
                first = made if drawn_only else None
            groups.setdefault(key, []).append((i, artifact, sc))
    return groups


def _run_tables(scenario: dict) -> dict | None:
    """A run's plant's drawn tables (:data:`DRAWN`), from its scenario; None when its plant is not a table."""
    plant = scenario.get("plant")
    return {k: plant[k] for k in DRAWN if k in plant} if isinstance(plant, dict) else None


def _part_tables(described: DescribedRuns, part: Any) -> list[dict] | None:
    """Each run of grid part ``part``'s plant drawn tables (:data:`DRAWN`), each run's own, made from the part's
    target columns (:meth:`~.plan.DescribedRuns.target_columns`) as :func:`_run_tables` finds them in its scenario;
    None when the part's runs are made one by one, name an FMU after their draws, a target is not a key of a drawn
    table, or a value there is not a number (:func:`_with_drawn` takes each run's own then, or parses it)."""
    columns = described.target_columns(part) if part.fmu is None else None
    plant = columns[0].get("plant") if columns is not None else None
    if not isinstance(plant, dict):
        return None
    base = {k: plant[k] for k in DRAWN if k in plant}
    puts = [(steps[1], steps[2], values) for steps, values in columns[1]]  # type: ignore[index]
    if not all(isinstance(t, dict) for t in base.values()) or any(k not in base for k, _, _ in puts):
        return None
    targets = {(k, key) for k, key, _ in puts}
    rest = [v for k, t in base.items() for key, v in t.items() if (k, key) not in targets]
    if not (_numbers(rest) and all(_numbers(values) for _, _, values in puts)):
        return None
    tables = []
    for j in range(part.stop - part.start):
        own = {k: dict(t) for k, t in base.items()}
        for k, key, values in puts:
            own[k][key] = values[j]
        tables.append(own)
    return tables


def _parsed(
    artifacts: dict[str, bytes], files: dict, sha: str, scenario: dict, seed: int, blobs: dict, i: int
) -> tuple | None:
    """Run ``i`` parsed for a block: its artifact, its scenario and its block's key; None when its inputs are wrong
    or it cannot step in a block (it runs alone, said in the log). ``files`` keeps each artifact parsed once."""
    from ..loop.block import refusal

    try:
        if sha not in files:
            files[sha] = artifact_from_bytes(artifacts[sha])
        artifact, path = files[sha]
        sc = _scenario(scenario, artifact_path=path, seed=seed, blobs=blobs, kind="sil")
    except GainlinkError:
        return None
    why = refusal(sc)
    if why is not None:
        log.info("campaign run %d of this task runs alone: %s", i, why)
        return None
    shape = json.dumps({k: v for k, v in sc.plant.items() if k not in DRAWN}, sort_keys=True, default=str)
    return artifact, sc, (sha, sc.controller, round(sc.duration / artifact.Ts), shape)


def _drawn_only(axes: tuple) -> bool:
    """Whether every draw axis sets, scales or shifts a value of the plant's drawn tables (:data:`DRAWN`:
    ``plant.parameters.M``), so that runs of one grid point differ only there and in their seeds."""
    steps = [path_steps(t) for a in axes for t in a.targets]
    return all(len(s) == 3 and s[0] == "plant" and s[1] in DRAWN and isinstance(s[2], str) for s in steps)


def _drawn_like(table: dict, parsed: Any, scenario: dict, seed: int) -> Any:
    """``scenario`` (a run's table) parsed, when it is ``table`` (parsed as ``parsed``, a SIL run a block takes)
    but for its seed and its plant's drawn numbers: ``parsed`` with those; None when it differs in anything else
    (it is parsed on its own)."""
    plant, base = scenario.get("plant"), table.get("plant")
    if scenario.keys() != table.keys() or not isinstance(plant, dict) or plant.keys() != base.keys():
        return None
    if any(scenario[k] != table[k] for k in scenario if k not in ("plant", "seed")):
        return None
    if any(plant[k] != base[k] for k in plant if k not in DRAWN):
        return None
    return _with_drawn(parsed, seed, {k: plant[k] for k in DRAWN if k in plant})


def _with_drawn(parsed: Any, seed: int, drawn: dict) -> Any:
    """``parsed`` (a scenario) with ``seed`` and the plant's drawn tables ``drawn`` (:data:`DRAWN`); None when a
    table is not one of numbers (only those are copied as :func:`_scenario`'s JSON copy makes them)."""
    if not all(isinstance(t, dict) and _numbers(t.values()) for t in drawn.values()):
        return None
    return _like(parsed, seed, {k: dict(t) for k, t in drawn.items()})


def _like(parsed: Any, seed: int, tables: dict) -> Any:
    """``parsed`` (a scenario) with ``seed`` and the plant's drawn tables ``tables`` (tables of numbers, its own)."""
    # copy.copy's own steps (a new instance, the fields' dict copied) without its __reduce_ex__ round (~3 us a run);
    # dataclasses.replace re-runs the 28 fields' __init__: 30-70 us a run here
    like = object.__new__(type(parsed))
    like.__dict__.update(parsed.__dict__, seed=int(seed), plant=parsed.plant | tables)
    return like


def _numbers(values: Iterable) -> bool:
    """Whether every one of ``values`` is an int or a float (not a bool, not numpy's)."""
    return _NUMBERS.issuperset(map(type, values))


_NUMBERS = frozenset((int, float))  # the types of a drawn table's values (not bool, not numpy's)


def _run_block(members: list, records: list, runs: list, blobs: dict, kept: Sequence[bool] | None = None) -> None:
    """Step ``members`` as one block and fill their ``records`` with it (a :class:`_Block`: the block's lists, not a
    dict a run); left empty (each runs alone) when their plants
    cannot step as one batch or the block fails with a GainlinkError (said once, in the log). A run whose plant
    cannot be built (a drawn number it refuses) is left out of the block and runs alone: it records its error.

    Without cyclic garbage collection: a 1,000-run block makes ~10^5 objects (dicts, views, results) and ~100 in
    cycles (counted after one); the collections they triggered cost ~0.1 us a run-step of the runs' ~1.2 (four
    pairs, load ~10)."""
    from ..loop.block import run_block
    from ..loop.scheduler import gc_paused

    where = {"host": socket.gethostname(), "pid": os.getpid(), "start": time.time()}
    cpu0 = time.thread_time()
    artifact = members[0][1]
    with gc_paused():
        try:
            results = run_block([sc for _, _, sc in members], artifact=artifact, library=_library(artifact))
        except GainlinkError as exc:
            log.info("a campaign block of %d runs failed (%s); running each alone", len(members), exc)
            return
        if results is None:
            log.info("a campaign block of %d runs steps one by one: its plants are not one vectorised kind",
                     len(members))  # fmt: skip
            return
        done = [(i, result) for (i, _, _), result in zip(members, results) if result is not None]
        for (i, _, _), result in zip(members, results):
            if result is None:
                log.info("campaign run %d of this task runs alone: its plant could not be built in its block", i)
        del result
        measures = measure_block([result for _, result in done], artifact)
        keep = None if kept is None else [kept[i] for i, _ in done]
        traces, stack = _downsampled([result.trace for _, result in done], keep)
        trees = results.metrics.trees if len(done) == len(members) and results.metrics.columnar else None
        kept_parts = _Block.parts([r for _, r in done], metrics=trees is None)
        positions = [i for i, _ in done]
        # The runs' objects (results, traces' views, metrics dicts) are let go before the clock stops: releasing them
        # is the runs' own work, as it is in a run alone; the block keeps only what its file is made from.
        del results, done
        share = _stopped(where, cpu0)
    share["cpu_s"] /= max(len(positions), 1)
    block = _Block(positions, *kept_parts, measures, traces, share | {"block": len(positions)}, stack=stack,
                   metric_trees=trees)  # fmt: skip
    for i in block.positions:
        records[i] = block
