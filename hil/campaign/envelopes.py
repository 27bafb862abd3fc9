"""The campaign report's envelopes: the percentiles of every output and command over time across the finished runs
(:func:`envelope_bands`), streamed from the store through histograms, and which runs they read
(:func:`traced_runs`, :func:`envelope_runs`: a rule of the plan alone)."""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import IO, Any, NamedTuple

import numpy as np
from gainlink.errors import GainlinkError

from .block_file import folder_key
from .figures import EnvelopeFigure
from .plan import CampaignPlan, PlannedRuns
from .rows import RunStatus, plan_draws, plan_ids
from .store import Store, members

PERCENTILES = (5, 25, 50, 75, 95)
ENVELOPE_BINS = 512
#: The most runs whose traces the envelopes read (:func:`envelope_runs`): 512 bins a sample show no more than a few
#: thousand runs' percentiles, and each run read costs the report ~0.1 ms of CPU.
ENVELOPE_RUNS = 2000
HISTOGRAM_VALUES = 1 << 20  # values binned and counted at a time: their float64 and index temporaries ~17 MB


def every_kth(ids: np.ndarray, cap: int) -> tuple[np.ndarray, int]:
    """Every k-th of ``ids`` from the first, k the smallest step that keeps them at most ``cap`` (all of them when they
    are that few); returns them and k."""
    every = max(1, -(-len(ids) // cap))
    return ids[::every], every


class Drawn(NamedTuple):
    """The runs :func:`envelope_runs` chose: their indices into the runs given, how many first draws of each grid
    point they are (``None``: every run) and the step taken through the first draw's runs (1 but when they alone are
    more than the cap)."""

    runs: np.ndarray
    draws: int | None
    every: int


def envelope_runs(draws: np.ndarray, cap: int = ENVELOPE_RUNS) -> Drawn:
    """The runs the envelopes read of runs whose draws are ``draws`` (each one's place among its grid point's runs,
    the runs in plan order): every run when they are at most ``cap``; else those of each grid point's first D draws,
    D the most that keeps them at most ``cap``; and when the first draw's runs alone are more (a grid of more than
    ``cap`` points), every k-th of them in plan order (:func:`every_kth`).

    A Monte-Carlo campaign's draws are independent and alike, so its first D draws are as fair a sample as any D of
    them, and each grid point's first D draws are neighbours in plan order: the runs chosen lie in a few row groups
    of the block files (:meth:`~.store.Store.trace_stacks` reads only those). A rule of the plan alone, so the same
    runs give the same picture however they were stored."""
    if len(draws) <= cap:
        return Drawn(np.arange(len(draws)), None, 1)
    within = np.cumsum(np.bincount(draws))
    first = int(np.searchsorted(within, cap, side="right"))
    if first:
        return Drawn(np.flatnonzero(draws < first), first, 1)
    picked, every = every_kth(np.flatnonzero(draws == 0), cap)
    return Drawn(picked, 1, every)


class Traced(NamedTuple):
    """The runs of a plan whose traces its campaign stores and its envelopes draw (:func:`traced_runs`): a mask over
    the plan's runs, their ids (ASCII bytes, sorted) and the rule's choice among the runs that can finish."""

    mask: np.ndarray
    ids: np.ndarray
    drawn: Drawn


def traced_runs(plan: CampaignPlan) -> Traced:
    """:func:`envelope_runs` of the plan's runs that can finish (each id where it is first planned, its grid point's
    design not failed), in plan order: a rule of the plan alone, so the client tells each block's worker which of its
    runs' traces to store before any has run, and the envelopes draw those of them that finish."""
    ids = plan_ids(plan)
    runnable = np.zeros(len(ids), bool)
    runnable[np.unique(ids, return_index=True)[1]] = True
    if isinstance(plan.runs, PlannedRuns):
        runnable &= ~plan.runs.failed
    else:
        runnable &= np.array([p.error is None for p in plan.runs], bool)
    at = np.flatnonzero(runnable)
    drawn = envelope_runs(plan_draws(plan)[at], ENVELOPE_RUNS)
    mask = np.zeros(len(ids), bool)
    mask[at[drawn.runs]] = True
    return Traced(mask, np.unique(ids[mask]), drawn)


def envelope_bands(
    store: Any,
    status: Mapping[str, str],
    *,
    bins: int = ENVELOPE_BINS,
    cap: int | None = None,
    traced: Traced | None = None,
) -> dict | None:
    """The percentiles (:data:`PERCENTILES`) of every output and command at each stored sample across the runs
    ``status`` (id -> ``pass`` or ``fail``, in plan order; a :class:`~.rows.RunStatus` with each run's draw, a plain
    mapping's runs each a draw of one grid point) whose traces have the most common shape, and the median of the
    failed ones among them; ``None`` without a stored trace.

    Bounded: of more than ``cap`` (default :data:`ENVELOPE_RUNS`) finished runs only those of each grid point's
    first draws are read (:func:`envelope_runs`; given the plan's ``traced`` runs, the finished among them, ``cap``
    unused: the runs whose traces the campaign stored), and the failed runs' median is over the failed runs among them
    (the same sample of the campaign: the failed runs elsewhere would put a run of every block file in the read);
    ``runs`` and ``failed`` count the runs of the most common shape so read, ``finished`` and ``failed_of`` all the
    distinct finished and failed runs, ``drawn`` the rule's choice (:class:`Drawn`). Only the row groups of the block
    files that hold a chosen run are read.

    In two steps, the runs read and binned (:func:`read_stack`, which needs no verdict), then their verdicts taken
    (:func:`stack_bands`): a cluster's worker does the first while the client judges the runs.

    Streamed: the block files are read once, one at a time (each trace shape's runs: each sample's smallest and largest
    finite value, the stack spilled as float32 to an anonymous temporary file in the campaign folder; the shapes are
    counted in the same pass), then the most common shape's spill is read back into each value's bin among ``bins``
    equal bins between them per sample and signal (2 bytes a value) and a histogram of them, so the memory is the
    histograms' and the bins', not the runs' float traces. A percentile is numpy's linear one (``np.nanpercentile``)
    over the runs read with each order statistic taken at the centre of its bin: within half a bin,
    ``(max - min) / (2 * bins)`` of that sample (the extremes over every run read), of the exact value (below a pixel
    of the plot). NaN samples are left out as nanpercentile leaves them; an infinite one counts in the end bin on its
    side.

    Returns ``{"t", "percentiles": (len(PERCENTILES), N, S), "failed_median": (N, S), "runs", "failed", "finished",
    "failed_of", "drawn", "outputs", "inputs", "half_bin": (N, S)}`` with the S signals the outputs then the
    commands.
    """
    request = envelope_request(status, cap=cap, traced=traced)
    return stack_bands(read_stack(store, request.chosen, bins=bins), request)


class EnvelopeRequest(NamedTuple):
    """What the envelopes take of the runs' verdicts (:func:`envelope_request`): the runs they read (the finished runs
    the rule chose; ASCII ids, sorted, distinct), the failed among them, how many distinct runs finished and failed in
    all, and the rule's choice."""

    chosen: np.ndarray
    failed: np.ndarray
    finished: int
    failed_of: int
    drawn: Drawn


def envelope_request(
    status: Mapping[str, str], *, cap: int | None = None, traced: Traced | None = None
) -> EnvelopeRequest:
    """:func:`envelope_bands`' runs of ``status``: its finished runs of each grid point's first draws, at most ``cap``
    (:func:`envelope_runs`), or the finished among the plan's ``traced`` runs."""
    cap = ENVELOPE_RUNS if cap is None else cap
    ids, draws, failing = _status_runs(status)
    if traced is None:
        drawn = envelope_runs(draws, cap)
        picked = drawn.runs
    else:
        drawn, picked = traced.drawn, np.flatnonzero(members(ids, traced.ids))
    chosen, failed = np.unique(ids[picked]), np.unique(ids[picked[failing[picked]]])
    return EnvelopeRequest(chosen, failed, len(ids), int(failing.sum()), drawn)


class StackMismatch(GainlinkError):
    """A stack read before the verdicts holds a run that is not among the runs they chose (a run with a stored trace
    that did not finish): its bands would not be theirs."""


class StackShape(NamedTuple):
    """Of the runs an :class:`EnvelopeStack` read, those of the most common trace shape: the times ``t``, the bins'
    ``lo`` and ``width`` per sample and signal (N, S), the runs (``names``, in the order of ``numbers``), each value's
    bin (``numbers``: (runs, N, S) uint16, the bin count for a NaN), the histogram of them all (``counts``: (N, S,
    bins)) and the signals' count (``outputs``, ``inputs``)."""

    t: np.ndarray
    lo: np.ndarray
    width: np.ndarray
    names: np.ndarray
    numbers: np.ndarray
    counts: np.ndarray
    outputs: int
    inputs: int


class EnvelopeStack(NamedTuple):
    """Runs' traces read for the envelopes before their verdicts are known (:func:`read_stack`): every run read
    (``read``: ASCII ids, sorted), the number of ``bins`` a sample and the most common shape's runs (``shape``; None
    without a stored trace). Plain arrays: a worker's result, moved to another process if need be."""

    read: np.ndarray
    bins: int
    shape: StackShape | None

    def __sizeof__(self) -> int:  # what Dask weighs the result by (a worker's memory, where its bands are made)
        arrays = (self.read, *(self.shape[:6] if self.shape is not None else ()))
        return object.__sizeof__(self) + sum(a.nbytes for a in arrays)


def read_stack(store: Any, ids: np.ndarray, *, bins: int = ENVELOPE_BINS) -> EnvelopeStack:
    """The stored traces of the runs ``ids`` (ASCII, sorted, distinct) read and binned for :func:`stack_bands`,
    which needs no verdict (:class:`EnvelopeStack`): each block file read once, its stacks spilled as float32 to an
    anonymous temporary file in the campaign folder with each trace shape's extremes, then the most common shape's
    (ties: the first met) read back into bins and their histogram."""
    with tempfile.TemporaryFile(dir=store.out) as spill:  # the stacks read once, kept as float32 for the 2nd pass
        seen, read = _spill_stacks(store, ids, spill)
        if not seen:
            return EnvelopeStack(read, bins, None)
        shape = max(seen, key=lambda k: seen[k].runs)
        one = seen[shape]
        lo, hi = np.nan_to_num(one.lo.astype(float)), np.nan_to_num(one.hi.astype(float))
        width = np.where(hi > lo, (hi - lo) / bins, 1.0)
        numbers, counts = _binned(one, spill, lo, width, bins)
    names = np.concatenate([n for _, n in one.chunks])
    return EnvelopeStack(read, bins, StackShape(one.t, lo, width, names, numbers, counts, shape[1], shape[2]))


def stack_bands(stack: EnvelopeStack, request: EnvelopeRequest) -> dict | None:
    """:func:`envelope_bands` of a stack read before the verdicts (:func:`read_stack`) and the verdicts' ``request``
    (:func:`envelope_request`): the failed runs' histogram counted from their bins, nothing read again. Raises
    :class:`StackMismatch` when the stack holds a run the verdicts did not choose."""
    if not members(stack.read, request.chosen).all():
        raise StackMismatch("the envelopes' traces read before the verdicts include a run that did not finish")
    one = stack.shape
    if one is None:
        return None
    failing = members(one.names, request.failed)
    lo, width = one.lo, one.width
    return {
        "t": one.t,
        "percentiles": _percentiles(one.counts, PERCENTILES, lo, width),
        "failed_median": _percentiles(_histogram(one.numbers[failing], stack.bins), (50,), lo, width)[0],
        "runs": len(one.names),
        "failed": int(failing.sum()),
        "finished": request.finished,
        "failed_of": request.failed_of,
        "drawn": request.drawn,
        "outputs": one.outputs,
        "inputs": one.inputs,
        "half_bin": width / 2,
    }


def cluster_stack(folder: tuple[str, tuple[int, int]], ids: np.ndarray) -> EnvelopeStack | None:
    """:func:`read_stack` as a cluster's task: of the campaign folder ``folder`` (its path and the
    :func:`~.block_file.folder_key` of its ``blocks``, the client's), ``None`` from a worker that does not see that
    folder (another machine's: the client then reads the traces itself)."""
    out, key = folder
    if folder_key(Path(out) / "blocks") != key:
        return None
    return read_stack(Store(out), ids)


def stack_png(stack: EnvelopeStack | None, request: EnvelopeRequest, figure: EnvelopeFigure) -> bytes | None:
    """``envelopes.png`` as a cluster's task, where ``stack`` was read (:func:`cluster_stack`): ``figure`` (its
    bands not yet made) with the bands of the stack and the verdicts' ``request``; ``None`` without a stack."""
    if stack is None:
        return None
    return replace(figure, bands=stack_bands(stack, request)).png()


def _binned(one: _Spilled, spill: IO[bytes], lo: np.ndarray, width: np.ndarray, bins: int) -> tuple:
    """The bins (runs, N, S) of the runs of ``one`` read back from ``spill`` (:data:`HISTOGRAM_VALUES` values at a
    time), and their histogram (N, S, ``bins``: :func:`_histogram`)."""
    numbers = np.empty((one.runs, *lo.shape), np.uint16)
    at = 0
    for sig in _spilled_runs(one, spill, lo.shape, max(1, HISTOGRAM_VALUES // lo.size)):
        numbers[at : at + len(sig)] = _bin_numbers(sig, lo, width, bins)
        at += len(sig)
    return numbers, _histogram(numbers, bins)


def _histogram(numbers: np.ndarray, bins: int) -> np.ndarray:
    """The histogram (N, S, ``bins``) of the bins ``numbers`` (runs, N, S), :data:`HISTOGRAM_VALUES` values at a
    time."""
    cells = int(np.prod(numbers.shape[1:]))
    counts = np.zeros(cells * (bins + 1), np.int64)
    step = max(1, HISTOGRAM_VALUES // max(cells, 1))
    for i in range(0, len(numbers), step):
        counts += _counts(numbers[i : i + step], bins)
    return counts.reshape(*numbers.shape[1:], bins + 1)[..., :bins]


def _spilled_runs(one: _Spilled, spill: IO[bytes], shape: tuple, step: int) -> Iterator[np.ndarray]:
    """The runs of ``one`` read back from ``spill`` (float32, ``shape`` a run), ``step`` runs at a time across its
    blocks' chunks (the few runs a chunk holds when only every k-th is read gathered with the next chunk's)."""
    held: list[np.ndarray] = []
    size = int(np.prod(shape))
    for at, names in one.chunks:
        spill.seek(at)
        for i in range(0, len(names), step):
            k = min(step, len(names) - i)
            held.append(np.fromfile(spill, np.float32, k * size).reshape(k, *shape))
            if sum(map(len, held)) >= step:
                yield np.concatenate(held)
                held.clear()
    if held:
        yield np.concatenate(held)


class _Spilled:
    """The runs of one trace shape spilled: their times, each sample's extremes, how many they are, and each block's
    place in the spill file with its runs."""

    def __init__(self, t: np.ndarray) -> None:
        self.t, self.lo, self.hi, self.runs = t, None, None, 0
        self.chunks: list[tuple[int, np.ndarray]] = []


def _spill_stacks(store: Any, ids: np.ndarray, spill: IO[bytes]) -> tuple[dict[tuple, _Spilled], np.ndarray]:
    """Read every block's traces of the runs ``ids`` (sorted, distinct) once, spill them to ``spill`` as float32 and
    note, per trace shape (samples, outputs, commands), what :func:`read_stack` needs: one pass, no separate read of
    the shapes. Returns them and every run read (sorted)."""
    seen: dict[tuple, _Spilled] = {}
    read: list[np.ndarray] = []
    at = 0
    for names, st in store.trace_stacks(ids, fields=("t", "y", "u")):
        shape = (st["t"].shape[1], st["y"].shape[2], st["u"].shape[2])
        one = seen.setdefault(shape, _Spilled(st["t"][0].astype(float)))
        sig = np.concatenate([st["y"], st["u"]], axis=2)
        one.lo, one.hi = _extremes(sig, one.lo, one.hi)
        one.chunks.append((at, names))
        one.runs += len(names)
        read.append(names)
        sig.tofile(spill)
        at += sig.nbytes
    spill.flush()
    return seen, np.sort(np.concatenate(read)) if read else np.zeros(0, "S1")


def _extremes(sig: np.ndarray, lo: np.ndarray | None, hi: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's smallest and largest finite value so far, with the runs ``sig`` (k, N, S) (NaN where none is)."""
    if np.isinf(sig).any():  # rare: the infinities left out as NaN, which fmin and fmax pass over
        sig = np.where(np.isinf(sig), np.nan, sig)
    mn, mx = np.fmin.reduce(sig, axis=0), np.fmax.reduce(sig, axis=0)
    return (mn, mx) if lo is None else (np.fmin(lo, mn), np.fmax(hi, mx))


def _status_runs(status: Mapping[str, str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct runs of ``status`` (id -> ``pass`` or ``fail``) as ASCII bytes in ``status``' order, each one's
    draw (a plain mapping's: its place, the runs one grid point's draws) and whether each failed. A
    :class:`~.rows.RunStatus` holds distinct runs already; a plain mapping's ids, made ASCII, are made distinct here
    (where each is first)."""
    if isinstance(status, RunStatus):
        return status.ids, status.draws, status.failed
    ids = np.array([i.encode("ascii", "replace") for i in status], dtype="S")
    failed = np.array([v == "fail" for v in status.values()], bool)
    draws = np.arange(len(ids))
    first = np.sort(np.unique(ids, return_index=True)[1])
    if len(first) < len(ids):
        ids, failed, draws = ids[first], failed[first], draws[first]
    return ids, draws, failed


def _bin_numbers(sig: np.ndarray, lo: np.ndarray, width: np.ndarray, bins: int) -> np.ndarray:
    """The bin of each value of ``sig`` (k, N, S) among ``bins`` bins from ``lo`` of ``width`` per sample and
    signal (uint16); a NaN's is ``bins``, past every bin."""
    nan = np.isnan(sig) if np.isnan(sig.min(initial=0.0)) else None  # NaN samples are rare: looked for once
    with np.errstate(invalid="ignore", over="ignore"):
        b = np.subtract(sig, lo)  # float64 (lo's): a float32 stack is widened here, no copy before; in place from here
        b /= width
    np.clip(b, 0, bins - 1, out=b)  # clipped first, then truncated: the floor of what is left, none negative
    if nan is not None:
        b[nan] = bins
    return b.astype(np.uint16)


def _counts(numbers: np.ndarray, bins: int) -> np.ndarray:
    """How many of the bins ``numbers`` (k, N, S; :func:`_bin_numbers`) fall in each bin of each (N, S) cell, as
    (N * S * (bins + 1)): each cell's last slot its NaNs'."""
    cells = numbers[0].size if len(numbers) else 0
    flat = numbers.astype(np.intp)
    flat += (np.arange(cells, dtype=np.intp) * (bins + 1)).reshape(numbers.shape[1:])
    return np.bincount(flat.ravel(), minlength=max(cells, 1) * (bins + 1))[: cells * (bins + 1)]


def _percentiles(counts: np.ndarray, qs: tuple[float, ...], lo: np.ndarray, width: np.ndarray) -> np.ndarray:
    """numpy's linear percentiles ``qs`` (len(qs), N, S) from histograms ``counts`` (N, S, bins), each order statistic
    at its bin's centre; NaN where a cell counts nothing. The cumulative counts are summed once for every ``q``, and
    each order statistic's bin is found by one ``searchsorted`` across the cells (each cell's cumulative counts
    lifted past the one before's)."""
    bins = counts.shape[-1]
    cum = np.cumsum(counts.reshape(-1, bins), axis=-1)
    n = cum[:, -1]
    lift = np.arange(len(n), dtype=np.int64) * (int(n.max(initial=0)) + 1)
    flat = (cum + lift[:, None]).ravel()
    start = np.arange(len(n), dtype=np.int64) * bins  # each cell's first bin in ``flat``
    out = []
    for q in qs:
        h = q / 100 * np.maximum(n - 1, 0)
        below, above = np.floor(h), np.ceil(h)
        # the bin of order statistic r: the first whose cumulative count passes r (the count of those at most r)
        at = [np.minimum(np.searchsorted(flat, r.astype(np.int64) + lift, side="right") - start, bins - 1)
              for r in (below, above)]  # fmt: skip
        value = [lo.ravel() + (b + 0.5) * width.ravel() for b in at]
        out.append(np.where(n > 0, value[0] + (h - below) * (value[1] - value[0]), np.nan).reshape(lo.shape))
    return np.stack(out)
