"""Run a campaign: plan it, submit the runs without a result to Dask, store each as it completes, merge.

FMUs go to the cluster once each (as tasks returning them, keyed by sha256); a task is
``execute_block(kind, artifacts, runs, fmus, ids=..., campaign=..., folder=...)`` (submitted as
:func:`.worker.execute_packed`, the ids and runs pickled into one argument): its runs (described by their grid points'
scenarios and their draws where the plan can, :meth:`.plan.PlannedRuns.task`) with the artifacts they use, inline
(SIL: a block of up to :data:`MAX_BLOCK` runs stepped together on the worker, in lockstep parts of at most
:data:`.worker.LOCKSTEP_RUNS`, :func:`batch_sizes`;
HIL: one run, keyed by its run id). A task makes its block's Parquet file on the worker and
writes it into the campaign folder itself when it sees the folder (a LocalCluster; the folder's device and inode
tell, not the hostname), returning only the file's name and the errors' reasons; a worker on another machine returns
the file's bytes for the client to write. Results come back as their tasks finish (Dask's done-callbacks) and each block
is noted as it completes (the client decodes no trace), so whatever finished before an interruption is kept. A task that
raised is retried once by Dask (``retries=1``); a batch still failing, or whose workers died under it
(``KilledWorker``), is submitted again one run per task, and a single run that fails so is recorded as an error with the
reason: one bad run costs no other run its result.
"""

from __future__ import annotations

import contextlib
import gc
import hashlib
import itertools
import logging
import pickle
import queue
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import GainlinkError
from gainlink.version import __version__

from .block_file import folder_key
from .block_layout import block_file_name
from .cluster import check_main_guard, dask_client
from .config import Campaign, CampaignError, load_campaign, parse_campaign
from .envelopes import EnvelopeRequest, cluster_stack, stack_png, traced_runs
from .figures import EnvelopeFigure, Figure, png_of
from .judged import JudgedPart
from .plan import CampaignPlan, RunPoint, describe_axes, plan_campaign, task_uses
from .report import Drawing, merge
from .rows import Verdicts, plan_ids
from .store import Store, refuse_foreign
from .worker import execute_packed

log = logging.getLogger(__name__)

Progress = Callable[[int, int, dict], None]
#: Runs a SIL task holds at most (one block file): its costs a task (Dask's, the file's, the client's and the
#: report's, ~10 ms) spread over more runs than one lockstep part (:data:`.worker.LOCKSTEP_RUNS`) holds. Its runs'
#: results live in the worker's memory until it ends; the parts' arrays do not (:class:`.worker._Block`). 5,000 against
#: 2,500 on 100,002 pendulum runs (2 workers, eight pairs alternated): the machinery 0.005-0.012 less of the runs' own
#: CPU in every pair, a worker's peak RSS ~300 MB against ~270; 10,000 no better than 5,000.
MAX_BLOCK = 5000
BLOCKS_PER_THREAD = 2
BLOCKS_IN_FLIGHT = 4


@dataclass(frozen=True)
class CampaignResult:
    """A finished campaign: where its report is, its runs (one row each) and the counts.

    ``rows`` is a read-only sequence of the runs' rows in plan order (each its point, its verdict and its stored
    record's row), made from the campaign folder's store when asked, a block file at a time
    (:class:`~.stored_rows.StoredRows`: iterate it to walk them; ``rows[i]`` reads run ``i``'s block file): no
    campaign, however many runs it has, holds them all in memory.

    ``reused`` runs had a result before this call (a resumed campaign; an error is not a result, so a run that
    errored is run again); ``executed`` ran now. Both count distinct runs (a run planned twice with the same
    inputs runs once); with the runs whose design failed they make up every distinct run.
    """

    out: Path
    rows: Sequence[dict]
    passed: int
    failed: int
    errors: int
    reused: int
    executed: int
    summary: str

    @property
    def total(self) -> int:
        """Every run of the campaign."""
        return len(self.rows)


class CampaignInterrupted(KeyboardInterrupt):
    """A campaign stopped by an interrupt (Ctrl-C): its cluster is stopped, every run stored so far is kept.

    ``finished`` of the ``total`` distinct runs have a result in ``out``; running the campaign again runs the
    others.
    """

    def __init__(self, *, out: Path, finished: int, total: int) -> None:
        super().__init__(f"campaign interrupted: {finished} of {total} runs have a result in {out}")
        self.out, self.finished, self.total = out, finished, total


def as_campaign(campaign: Campaign | str | Path | Mapping) -> Campaign:
    """A :class:`Campaign` from a parsed one, a TOML file path, or a mapping."""
    if isinstance(campaign, Campaign):
        return campaign
    if isinstance(campaign, (str, Path)):
        return load_campaign(campaign)
    return parse_campaign(campaign)


def plan_doc(plan: CampaignPlan) -> dict:
    """``plan.json``: the campaign, its runs' ids in plan order (an index's run) and their sha256. A run's inputs are
    in its record in the store (``inputs``), which is what ``campaign show`` replays: not every run's scenario
    again here (814 bytes a run of the shipped pendulum campaign: 81 MB at 100,000 runs, written through json's Python
    encoder)."""
    c = plan.campaign
    ids = [i.decode("ascii") for i in plan.runs.ids]
    return {
        "campaign": {
            "name": c.name,
            "kind": c.kind,
            "seed": c.seed,
            "runs_per_point": c.runs,
            "spec": str(c.spec_path) if c.spec_path else None,
            "artifact": str(c.artifact_path) if c.artifact_path else None,
            "axes": describe_axes(c),
            "description": c.description,
            "traces": c.traces,
            "gainlink": __version__,
        },
        "run_ids": ids,
        "runs_sha256": hashlib.sha256("\n".join(ids).encode("ascii")).hexdigest(),
    }


def run(
    campaign: Campaign | str | Path | Mapping,
    *,
    out: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Progress | None = None,
    batch: int | None = None,
    plots: bool = True,
) -> CampaignResult:
    """Run every run of a campaign that has no result in ``out`` yet, then write the merged report.

    Parameters
    ----------
    campaign : Campaign, path or mapping
        The campaign (a TOML file, or its content as a dict).
    out : path
        The campaign folder: results by run id, ``campaign.json``, ``campaign.csv``, plots, summary.
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:8786``); default: a LocalCluster on this machine.
    workers : int, optional
        LocalCluster process workers (default: one per CPU).
    progress : callable, optional
        ``progress(done, total, run)`` after each run is stored; ``run`` is its ``id``, ``status`` (``done`` or
        ``error``) and an error's ``reason`` (the full record: ``Store(out).record(id)``).
    batch : int, optional
        Runs per Dask task (default: :func:`batch_sizes`; results are still stored, retried and reported
        per run).
    plots : bool
        Draw the report's PNGs (``envelopes.png``, ``scatter.png``); without, the report is its JSON, CSV and
        text only.

    Returns
    -------
    CampaignResult

    Raises
    ------
    CampaignError
        The campaign file or an option is wrong (nothing written).
    UnguardedMainError
        Called, for a LocalCluster (no ``scheduler``), from a script's top level outside
        ``if __name__ == "__main__":`` (its workers would run the script again): refused before anything is planned.
    CampaignInterrupted
        On an interrupt (a ``KeyboardInterrupt``): the cluster is stopped and every run stored so far is kept.

    Examples
    --------
    >>> import gainlink.hil.campaign as campaign
    >>> result = campaign.run("examples/campaigns/pendulum_mass_uncertainty.toml", out="out/c")  # doctest: +SKIP
    >>> result.passed / result.total                                                             # doctest: +SKIP
    """
    if scheduler is None:  # a LocalCluster's workers import the calling script again
        check_main_guard()
    _check_counts(batch=batch, workers=workers)  # before anything is planned or written
    with _gc_frozen():
        return _run(as_campaign(campaign), out=out, scheduler=scheduler, workers=workers, progress=progress,
                    batch=batch, plots=plots)  # fmt: skip


@contextlib.contextmanager
def _gc_frozen() -> Iterator[None]:
    """The objects this process holds when a campaign starts (its modules', ~200,000 here) left out of the cyclic
    garbage collections while it runs: they outlive it, and each full collection walked them all again (measured in
    the client of a 10,002-run campaign: one full collection, ~0.1 s of its 1.2 CPU-s; at 100,002 runs two, 0.2 s).
    Given back to the collector when the campaign ends, however it ends. A caller that froze objects itself keeps
    them frozen, and the campaign's objects are then collected as usual (an unfreeze would undo the caller's)."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _run(
    campaign: Campaign,
    *,
    out: str | Path,
    scheduler: str | None,
    workers: int | None,
    progress: Progress | None,
    batch: int | None,
    plots: bool,
) -> CampaignResult:
    """:func:`run` of a campaign read and options checked."""
    plan = plan_campaign(campaign)
    store = _prepared_store(plan, out)
    distinct, finished = _distinct_runs(plan, store)
    total, reused = int(distinct.sum()), int((distinct & finished).sum())
    todo = int((distinct & ~finished & ~plan.runs.failed).sum())
    done = total - todo
    if todo:
        try:
            with dask_client(scheduler=scheduler, workers=workers) as client, _verdicts(plan) as verdicts:
                threads = sum(client.nthreads().values())
                sizes = batch_sizes(campaign.kind, todo, threads, batch=batch)
                blocks = _blocks(plan, store, sizes, distinct & ~finished)
                _submit_and_store(
                    client,
                    plan,
                    blocks,
                    store,
                    done=done,
                    total=total,
                    progress=progress,
                    window=threads,
                    verdicts=verdicts,
                )
                drawing = _ClusterDrawing(client, store)
                return _result(
                    plan, store, reused=reused, executed=todo, plots=plots, drawing=drawing, verdicts=verdicts
                )
        except KeyboardInterrupt:  # the block closed the client (and the LocalCluster) on its way out
            # read again from the folder: workers write their blocks themselves, some the client had not yet heard of
            stored = int((distinct & Store(store.out).finished_mask(plan.runs.ids)).sum())
            raise CampaignInterrupted(out=store.out, finished=stored, total=total) from None
    return _result(plan, store, reused=reused, executed=todo, plots=plots)


def _prepared_store(plan: CampaignPlan, out: str | Path) -> Store:
    """The campaign folder ``out`` with its inputs written (refused in one line, before anything is written, when it
    holds another campaign's). ``plan.json``'s document (a string a run) is not kept while the campaign runs."""
    doc = plan_doc(plan)
    refuse_foreign(out, doc)
    store = Store(out, campaign=plan.campaign.name)
    store.prepare(plan, plan_doc=doc)
    return store


def _check_counts(*, batch: int | None, workers: int | None) -> None:
    """``batch`` and ``workers`` are whole numbers >= 1 when given."""
    for name, value in (("batch", batch), ("workers", workers)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise CampaignError(f"campaign: {name} must be a whole number >= 1, not {value!r}")


def _distinct_runs(plan: CampaignPlan, store: Store) -> tuple[np.ndarray, np.ndarray]:
    """By run, in plan order: whether it is the first of its id (a run planned twice with the same inputs runs once)
    and whether the store holds its result; from the plan's ids, without making a run."""
    ids = plan.runs.ids
    distinct = np.zeros(len(ids), bool)
    distinct[np.unique(ids, return_index=True)[1]] = True
    return distinct, store.finished_mask(ids)


def _blocks(plan: CampaignPlan, store: Store, sizes: list[int], pending: np.ndarray) -> Iterator[np.ndarray]:
    """The runs to submit (``pending``: a distinct run without a result), in plan order, cut into blocks of
    ``sizes``: each block the plan indices of its runs (int64), not its runs, which are made when it is submitted
    (:class:`_Submitter`) and not held while it runs. Those whose design failed are stored as errors here, a block
    at a time, instead of being submitted."""
    failed = np.flatnonzero(pending & plan.runs.failed)
    for start in range(0, len(failed), MAX_BLOCK):
        points = [plan.runs[int(k)] for k in failed[start : start + MAX_BLOCK]]
        store.put(points, kind=plan.campaign.kind, results=[{"status": "error", "reason": p.error} for p in points])
    todo = np.flatnonzero(pending & ~plan.runs.failed)
    for start, size in zip(itertools.accumulate(sizes, initial=0), sizes):
        if start < len(todo):
            yield todo[start : start + size]
    if sum(sizes) < len(todo):  # sizes cover ``todo`` (batch_sizes); a remainder is one more block
        yield todo[sum(sizes) :]


@contextlib.contextmanager
def _verdicts(plan: CampaignPlan) -> Iterator[Verdicts]:
    """The campaign's verdicts while it runs, each block's filed in as the block is stored (judged by its worker),
    closed when the campaign ends (:func:`~.report.merge` completes them)."""
    verdicts = Verdicts(plan.campaign.criteria, plan_ids(plan))
    try:
        yield verdicts
    finally:
        verdicts.close()


def _result(
    plan: CampaignPlan,
    store: Store,
    *,
    reused: int,
    executed: int,
    plots: bool,
    drawing: Drawing | None = None,
    verdicts: Verdicts | None = None,
) -> CampaignResult:
    """Merge the stored runs into the campaign report and count them (``drawing``: where its figures are made besides
    here, :func:`~.report.drawn_figures`; ``verdicts``: those of the blocks judged ahead, :func:`~.report.merge`)."""
    summary, rows, counts = merge(plan, store, plots=plots, drawing=drawing, verdicts=verdicts)
    return CampaignResult(
        out=store.out,
        rows=rows,
        passed=counts["pass"],
        failed=counts["fail"],
        errors=counts["error"],
        reused=reused,
        executed=executed,
        summary=summary,
    )


class _ClusterDrawing:
    """The report's figures made as tasks on the cluster, whose workers are idle once the runs are stored
    (:class:`~.report.Drawing`): the envelopes' traces read and binned on a worker that sees the campaign folder while
    the client judges the runs, their bands and figure made there, the scatter drawn on another meanwhile (see
    :func:`~.report.drawn_figures`)."""

    def __init__(self, client: Any, store: Store) -> None:
        self.client = client
        self.folder = (str(store.out.resolve()), folder_key(store.blocks))  # as _Submitter's: seen, or not, by each

    def draw(self, figure: Figure) -> Any:
        return self._submit(png_of, figure)

    def read_stack(self, ids: np.ndarray) -> Any:
        return self._submit(cluster_stack, self.folder, ids)

    def stack_png(self, stack: Any, request: EnvelopeRequest, figure: EnvelopeFigure) -> Any:
        return self._submit(stack_png, stack, request, figure)

    def _submit(self, fn: Callable, *args: Any) -> Any:
        return self.client.submit(fn, *args, key=f"gainlink-report-{uuid.uuid4().hex}", retries=1)


def _data(value: bytes) -> bytes:
    """A campaign input (an FMU archive) as the result of a task."""
    return value


def batch_sizes(kind: str, runs: int, threads: int, *, batch: int | None = None) -> list[int]:
    """Runs per Dask task, in the order of submission.

    HIL: 1 (a run lasts seconds). SIL: blocks stepped together on the worker (:mod:`gainlink.hil.loop.block`, in
    lockstep parts of at most :data:`.worker.LOCKSTEP_RUNS`), as few as keep every thread busy
    (:data:`BLOCKS_PER_THREAD` each) and no larger than :data:`MAX_BLOCK` runs, the runs shared evenly, and as many
    blocks as a whole number of rounds of the threads: 5 blocks on 2 threads would leave one thread running the
    fifth alone while the other waits (a sixth of the campaign's runs time lost), 6 do not. ``batch`` fixes the
    size instead.
    """
    if batch is not None or kind == "hil":
        size = batch or 1
        return [size] * (runs // size) + ([runs % size] if runs % size else [])
    if not runs:
        return []
    threads = max(threads, 1)
    rounds = -(-max(-(-runs // MAX_BLOCK), threads * BLOCKS_PER_THREAD) // threads)
    count = min(runs, rounds * threads)
    return [runs // count + (1 if i < runs % count else 0) for i in range(count)]


def _store_answer(store: Store, data: Any, ids: list[str], verdicts: Verdicts | None = None) -> list[dict]:
    """Store a task's answer for runs ``ids``: the block file a worker wrote (a few numbers), or its bytes, with the
    runs judged by the worker (filed into ``verdicts``) when it did; a worker that answered something else is named."""
    if isinstance(data, dict) and "block" in data:
        stored = store.took_block(data, ids)
    else:
        stored = store.put_block(_block_bytes(data))
    if verdicts is not None and isinstance(data, dict) and isinstance(data.get("judged"), JudgedPart):
        verdicts.add(block_file_name(ids), data["judged"])
    return stored


def _block_bytes(data: Any) -> bytes:
    """A task's answer: the bytes of a block file, alone or as a dict's ``data``; a worker that answered something
    else is named (a dict by its keys)."""
    bytes_ = data.get("data") if isinstance(data, dict) else data
    if not isinstance(bytes_, bytes):
        what = f"a dict of {sorted(map(str, data))}" if isinstance(data, dict) else type(data).__name__
        raise GainlinkError(
            f"a worker returned {what}, not a block of records: is it running "
            f"another gainlink version than this client ({__version__})?"
        )
    return bytes_


class _Submitter:
    """Submits blocks of runs to Dask, each given by its plan indices; a block that failed is submitted again one run
    per task."""

    def __init__(self, client: Any, plan: CampaignPlan, store: Store) -> None:
        self.client, self.plan, self.kind = client, plan, plan.campaign.kind
        # where a worker that sees the campaign folder writes its block file itself (folder_key: not the hostname)
        self.folder = (str(store.blocks.resolve()), folder_key(store.blocks))
        # FMU archives go to the cluster once each, as tasks returning them (not scattered data): a task's result
        # lost with its worker is computed again from the graph, scattered data would be gone for good. Artifacts
        # (a few kB) travel inside each task: a task with no dependency goes to whichever worker is free, instead
        # of queueing on the worker that happens to hold the artifact.
        self.blobs = {sha: client.submit(_data, data, key=f"gainlink-fmu-{sha}") for sha, data in plan.blobs.items()}
        # whose traces the workers store (envelopes.traced_runs), None for every run's
        self.traced = None if plan.campaign.traces == "all" else traced_runs(plan).mask

    def ids(self, block: np.ndarray) -> list[str]:
        """The run ids of the plan indices ``block``."""
        return [i.decode("ascii") for i in self.plan.runs.ids[block].tolist()]

    def points(self, block: np.ndarray) -> list[RunPoint]:
        """The runs of the plan indices ``block``, made again (a few kB each: made when needed, never held)."""
        return [self.plan.runs[k] for k in block.tolist()]

    def submit(self, block: np.ndarray) -> Any:
        """One task running the runs of plan indices ``block`` in order (retried once by Dask when it raises). The
        runs travel as the plan's task gives them (:meth:`.plan.PlannedRuns.task`: described, each grid point's
        scenario once and each run's draws and seed as numbers, or else each run's inputs made here), without their
        ids' making (the plan holds them), and are dropped once pickled into the task."""
        ids, runs = self.ids(block), self.plan.runs.task(block)
        kept = None if self.traced is None or self.traced[block].all() else self.traced[block]
        shas, fmus = task_uses(runs)
        needed = {s: f for s, f in self.blobs.items() if s in fmus}
        key = f"gainlink-run-{ids[0]}" if len(ids) == 1 else f"gainlink-batch-{ids[0]}-{len(ids)}"
        return self.client.submit(
            execute_packed,
            self.kind,
            {s: self.plan.artifacts[s] for s in shas},
            pickle.dumps((ids, runs, kept), protocol=pickle.HIGHEST_PROTOCOL),
            needed,
            campaign=self.plan.campaign.name,
            folder=self.folder,
            criteria=self.plan.campaign.criteria,
            key=key,
            retries=1,
            pure=False,
        )


class _Finished:
    """The futures added, each given back once as it finishes (done, failed or cancelled), until none is left: Dask's
    callback thread puts a finished future on a queue the caller blocks on. (``distributed.as_completed`` wakes its
    caller ten times a second to look instead: with it the main thread took 1.8-2.1 us of CPU a run while the runs
    went, with this 1.5-1.6; 30,002 runs on 2 workers.)"""

    def __init__(self) -> None:
        self._done: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._pending = 0

    def add(self, future: Any) -> None:
        self._pending += 1
        future.add_done_callback(self._done.put)

    def __iter__(self) -> Iterator[Any]:
        while self._pending:
            future = self._done.get()
            self._pending -= 1
            yield future


def _submit_and_store(
    client: Any,
    plan: CampaignPlan,
    blocks: Iterator[np.ndarray],
    store: Store,
    *,
    done: int,
    total: int,
    progress: Progress | None,
    window: int,
    verdicts: Verdicts | None = None,
) -> None:
    """Submit ``blocks`` (plan indices) as they are generated, at most :data:`BLOCKS_IN_FLIGHT` per thread
    (``window``) at a time, and store each as it completes. The client holds each block in flight as its plan indices
    (8 bytes a run), not its runs: a run is made to be pickled into its task, and again only if its task failed. The
    runs a worker judged are filed into ``verdicts`` as their block is stored."""
    from asyncio import CancelledError

    kind = plan.campaign.kind
    submitter = _Submitter(client, plan, store)
    futures: dict[Any, np.ndarray] = {}
    finished = _Finished()
    for block in itertools.islice(blocks, max(window, 1) * BLOCKS_IN_FLIGHT):
        first = submitter.submit(block)
        futures[first] = block
        finished.add(first)
    for fut in finished:
        block = futures.pop(fut)
        try:
            stored = _store_answer(store, fut.result(), submitter.ids(block), verdicts)
        except (Exception, CancelledError) as exc:  # retried once already; KilledWorker: its workers died
            fut.release()
            reason = f"{type(exc).__name__}: {exc}"
            if len(block) > 1:  # each run alone: only the run at fault fails
                log.info("a batch of %d runs failed (%s); running each alone", len(block), reason)
                for i in range(len(block)):
                    single = submitter.submit(block[i : i + 1])
                    futures[single] = block[i : i + 1]
                    finished.add(single)
                continue
            stored = store.put(submitter.points(block), kind=kind, results=[{"status": "error", "reason": reason}])
        fut.release()
        for nxt in itertools.islice(blocks, 1):  # the next block takes the finished one's place
            queued = submitter.submit(nxt)
            futures[queued] = nxt
            finished.add(queued)
        for k, record in zip(block.tolist(), stored):
            done += 1
            if record["status"] == "error":
                log.warning("run %s (%d) failed: %s", record["id"], k, record["reason"])
            if progress is not None:
                progress(done, total, record)
