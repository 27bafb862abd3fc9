"""The campaign report's envelopes: the percentiles of every output and command over time across the finished runs
(:func:`envelope_bands`), streamed from the store through histograms, and which runs they read
(:func:`traced_runs`, :func:`envelope_runs`: a rule of the plan alone)."""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Mapping
from typing import IO, Any, NamedTuple

import numpy as np

from .plan import CampaignPlan, PlannedRuns
from .rows import RunStatus, plan_draws, plan_ids
from .store import members

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

    Streamed: the block files are read once, one at a time (each trace shape's runs: each sample's smallest and largest
    finite value, the stack spilled as float32 to an anonymous temporary file in the campaign folder; the shapes are
    counted in the same pass), then the most common shape's spill is read back a block at a time into a histogram of
    ``bins`` equal bins between them per sample and signal, so the memory is the histograms', not the runs'. A
    percentile is numpy's linear one (``np.nanpercentile``) over the runs read with each order statistic taken at the
    centre of its bin: within half a bin, ``(max - min) / (2 * bins)`` of that sample (the extremes over every run
    read), of the exact value (below a pixel of the plot). NaN samples are left out as nanpercentile leaves them; an
    infinite one counts in the end bin on its side.

    Returns ``{"t", "percentiles": (len(PERCENTILES), N, S), "failed_median": (N, S), "runs", "failed", "finished",
    "failed_of", "drawn", "outputs", "inputs", "half_bin": (N, S)}`` with the S signals the outputs then the
    commands.
    """
    cap = ENVELOPE_RUNS if cap is None else cap
    ids, draws, failing = _status_runs(status)
    if traced is None:
        drawn = envelope_runs(draws, cap)
        picked = drawn.runs
    else:
        drawn, picked = traced.drawn, np.flatnonzero(members(ids, traced.ids))
    chosen, failed = ids[picked], ids[picked[failing[picked]]]
    with tempfile.TemporaryFile(dir=store.out) as spill:  # the stacks read once, kept as float32 for the 2nd pass
        seen = _spill_stacks(store, np.unique(chosen), np.unique(failed), spill)
        if not seen:
            return None
        shape = max(seen, key=lambda k: seen[k].runs)  # the most common shape; ties: the first met
        one = seen[shape]
        lo, hi = np.nan_to_num(one.lo.astype(float)), np.nan_to_num(one.hi.astype(float))
        width = np.where(hi > lo, (hi - lo) / bins, 1.0)
        counts = _histograms(one, spill, lo, width, bins)
    pct = _percentiles(counts[0], PERCENTILES, lo, width)
    return {
        "t": one.t,
        "percentiles": pct,
        "failed_median": _percentiles(counts[1], (50,), lo, width)[0],
        "runs": one.runs,
        "failed": int(sum(b.sum() for _, b in one.chunks)),
        "finished": len(ids),
        "failed_of": int(failing.sum()),
        "drawn": drawn,
        "outputs": shape[1],
        "inputs": shape[2],
        "half_bin": width / 2,
    }


def _histograms(one: _Spilled, spill: IO[bytes], lo: np.ndarray, width: np.ndarray, bins: int) -> np.ndarray:
    """The histograms (2, N, S, ``bins``) of the runs of ``one`` read back from ``spill``: of the runs chosen for the
    percentiles, and of the failed runs chosen for their median. Each run is binned once, :data:`HISTOGRAM_VALUES`
    values at a time (:func:`_spilled_runs`; a count is a pass over every bin, so the fewer the better)."""
    cells = lo.size * bins
    counts = np.zeros((2, cells), np.int64)
    for sig, failed in _spilled_runs(one, spill, lo.shape, max(1, HISTOGRAM_VALUES // lo.size)):
        where = _bin_numbers(sig, lo, width, bins)
        counts[0] += _counts(where, cells)
        if failed.any():  # the failed runs' bins are theirs of all runs: counted, not made again
            counts[1] += _counts(where if failed.all() else where[failed], cells)
    return counts.reshape(2, *lo.shape, bins)


def _spilled_runs(one: _Spilled, spill: IO[bytes], shape: tuple, step: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The runs of ``one`` read back from ``spill`` (float32, ``shape`` a run), ``step`` runs at a time across its
    blocks' chunks (the few runs a chunk holds when only every k-th is read gathered with the next chunk's), each with
    which of them the failed median counts."""
    held: list[np.ndarray] = []
    bad: list[np.ndarray] = []
    for at, failed in one.chunks:
        spill.seek(at)
        for i in range(0, failed.size, step):
            part = failed[i : i + step]
            held.append(np.fromfile(spill, np.float32, part.size * int(np.prod(shape))).reshape(part.size, *shape))
            bad.append(part)
            if sum(map(len, bad)) >= step:
                yield np.concatenate(held), np.concatenate(bad)
                held.clear()
                bad.clear()
    if bad:
        yield np.concatenate(held), np.concatenate(bad)


class _Spilled:
    """The runs of one trace shape spilled (every one counts in the percentiles): their times, each sample's extremes,
    how many they are, and each block's place in the spill file with which of its runs the failed median counts."""

    def __init__(self, t: np.ndarray) -> None:
        self.t, self.lo, self.hi, self.runs = t, None, None, 0
        self.chunks: list[tuple[int, np.ndarray]] = []


def _spill_stacks(store: Any, chosen: np.ndarray, failing: np.ndarray, spill: IO[bytes]) -> dict[tuple, _Spilled]:
    """Read every block's traces of the runs ``chosen`` (the percentiles', sorted and distinct; ``failing`` the failed
    median's among them) once, spill them to ``spill`` as float32 and note, per trace shape (samples, outputs,
    commands), what :func:`envelope_bands` needs: one pass, no separate read of the shapes."""
    seen: dict[tuple, _Spilled] = {}
    at = 0
    for names, st in store.trace_stacks(chosen, fields=("t", "y", "u")):
        shape = (st["t"].shape[1], st["y"].shape[2], st["u"].shape[2])
        one = seen.setdefault(shape, _Spilled(st["t"][0].astype(float)))
        sig = np.concatenate([st["y"], st["u"]], axis=2)
        one.lo, one.hi = _extremes(sig, one.lo, one.hi)
        one.chunks.append((at, members(names, failing)))  # the stacks hold the runs ``chosen`` only
        one.runs += len(names)
        sig.tofile(spill)
        at += sig.nbytes
    spill.flush()
    return seen


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
    signal, numbered across the (N, S) cells (cell * bins + bin); a NaN's is ``N * S * bins``, past every cell's."""
    nan = np.isnan(sig) if np.isnan(sig.min(initial=0.0)) else None  # NaN samples are rare: looked for once
    with np.errstate(invalid="ignore", over="ignore"):
        b = np.subtract(sig, lo)  # float64 (lo's): a float32 stack is widened here, no copy before; in place from here
        b /= width
    np.clip(b, 0, bins - 1, out=b)  # clipped first, then truncated: the floor of what is left, none negative
    b += np.arange(lo.size, dtype=float).reshape(lo.shape) * bins  # whole numbers: exact in a float64
    if nan is not None:
        b[nan] = lo.size * bins
    return b.astype(np.int64)


def _counts(where: np.ndarray, cells: int) -> np.ndarray:
    """How many of the bin numbers ``where`` (:func:`_bin_numbers`) fall in each of ``cells`` bins, NaN's left out."""
    return np.bincount(where.ravel(), minlength=cells + 1)[:cells]


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
