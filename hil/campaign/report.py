"""The merged campaign report: ``campaign.json``, ``campaign.csv``, plots and a one-screen summary.

- ``campaign.json``: the campaign (axes, criteria), counts, the pass fraction and IAE quantiles per grid point,
  and the failures (the :data:`~.rows.FAILURES_LIMIT` worst runs that did not pass: index, id, status, axis values,
  reasons); not every run: a run's whole row (its verdict, metrics and measures) is the store's, made when asked
  (``CampaignResult.rows``, :class:`~.stored_rows.StoredRows`; ``gainlink campaign show DIR --run ID``);
- ``campaign.csv``: one row per run (axis values, status, reasons, the main metrics);
- ``envelopes.png``: percentiles (5-95, 25-75, median) of every output and command over time across
  the finished runs (at most :data:`ENVELOPE_RUNS` of them, each grid point's first draws, as its title says),
  with the median of the failed runs among them dashed;
- ``scatter.png``: for each drawn (or numeric grid) axis, each tracked output's IAE against it, failed
  runs marked (at most :data:`SCATTER_RUNS` of each status, every k-th in plan order, as its title says; the legend
  counts every run);
- ``failures.txt``: the failure table (run, axis values, reasons), worst first;
- ``summary.txt``: counts, pass fraction per grid point, the worst runs and how to replay one.

Verdicts are computed here from the stored measures, so changing the criteria and merging again needs
no run (``gainlink campaign show DIR`` re-merges).
"""

from __future__ import annotations

import csv
import json
import logging
import tempfile
from collections import Counter
from collections.abc import Callable, Iterator, Mapping
from functools import partial
from typing import IO, Any, NamedTuple

import numpy as np
from gainlink.fileio import atomic_writer, publish_files

from .block_layout import MEASURE_CELLS, METRIC_CELLS
from .figures import EnvelopeFigure, Figure, ScatterFigure, ScatterPanel, ordinal
from .plan import CampaignPlan, PlannedRuns, describe_axes
from .rows import FAILURES_LIMIT, RunStatus, Tally, Verdicts, head_texts, plan_draws, plan_ids
from .store import members
from .stored_rows import StoredRows

log = logging.getLogger(__name__)

PERCENTILES = (5, 25, 50, 75, 95)
ENVELOPE_BINS = 512
#: The most runs whose traces the envelopes read (:func:`envelope_runs`): 512 bins a sample show no more than a few
#: thousand runs' percentiles, and each run read costs the report ~0.1 ms of CPU.
ENVELOPE_RUNS = 2000
MAX_POINT_LINES = 30
#: The most runs of each status (passed, failed) the scatter plot draws (:func:`scatter_runs`): a run drawn costs the
#: figure ~10 µs of CPU in the shipped pendulum's three panels, and a few thousand show the cloud as all of them do.
SCATTER_RUNS = 2000
HISTOGRAM_VALUES = 1 << 20  # values binned and counted at a time: their float64 and index temporaries ~17 MB


def csv_head(plan: CampaignPlan, tracked: set[str], outs: set[str]) -> list[str]:
    """``campaign.csv``'s header: the run, its axes, measures and the main metrics of each tracked output."""
    return [
        "index",
        "id",
        "status",
        "reasons",
        *_axes(plan),
        "seed",
        "complete",
        *MEASURE_CELLS,
        *[f"{t}_{k}" for t in sorted(tracked) for k in METRIC_CELLS],
        *[f"{o}_final" for o in sorted(outs)],
        "artifact_sha256",
    ]


def _axes(plan: CampaignPlan) -> list[str]:
    return [a.name for a in (*plan.campaign.grid, *plan.campaign.draws)]


def failures_text(tally: Tally) -> str:
    """The failure table: failed and erroneous runs, worst (largest IAE) first, errors last (the
    :data:`~.rows.FAILURES_LIMIT` first)."""
    bad = tally.failure_rows()
    lines = [f"{'index':>6}  {'id':<20}  {'status':<6}  values  ->  reasons"]
    for r in bad:
        vals = ", ".join(f"{k}={_short(v)}" for k, v in r["values"].items())
        lines.append(f"{r['index']:>6}  {r['id']:<20}  {r['status']:<6}  {vals}  ->  {'; '.join(r['reasons'])}")
    if tally.bad > len(bad):
        lines.append(f"... and {tally.bad - len(bad)} more (campaign.csv has them all)")
    if not tally.bad:
        lines.append("(no failed run)")
    return "\n".join(lines) + "\n"


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    text = v if isinstance(v, str) else json.dumps(v)
    return text if len(text) <= 30 else text[:27] + "..."


def summary_text(
    plan: CampaignPlan, tally: Tally, points: list[dict], *, out: Any, plots: bool = True, traced: Traced | None = None
) -> str:
    """A one-screen summary of the campaign (``plots``: whether the report has its PNGs; ``traced``: the runs whose
    traces it stores, when not every run's)."""
    c = plan.campaign
    counts = tally.counts
    n = tally.runs
    lines = [
        f"Campaign {c.name} ({c.kind}): {n} runs, {counts['pass']} passed ({100 * counts['pass'] / max(n, 1):.1f}%), "
        f"{counts['fail']} failed, {counts['error']} errors"
        + (f", {counts['missing']} missing" if counts["missing"] else "")
    ]
    unit = _iae_unit(_signals(plan)).replace("[", "").replace("]", "")  # " m s" or ""
    if len(points) > 1:
        lines.append("  per grid point:")
        for p in points[:MAX_POINT_LINES]:
            vals = ", ".join(f"{k}={_short(v)}" for k, v in p["values"].items())
            iae = (
                ""
                if p["iae_median"] is None
                else f"  IAE median {p['iae_median']:.4g}{unit} p95 {p['iae_p95']:.4g}{unit}"
            )
            lines.append(f"    {vals}: {p['pass']}/{p['runs']} passed ({100 * p['pass_fraction']:.1f}%){iae}")
        if len(points) > MAX_POINT_LINES:
            lines.append(f"    ... {len(points) - MAX_POINT_LINES} more grid points in campaign.json (points)")
    if tally.failed:
        lines.append("  runs failing each criterion: " + ", ".join(f"{k} {v}" for k, v in tally.failed.most_common()))
    lines += _model_lines(tally)
    worst = tally.worst_runs
    if worst:
        lines.append("  worst IAE: " + ", ".join(f"run {i} {rid} ({iae:.4g}{unit}, {st})" for i, rid, iae, st in worst))
        lines.append(f"  replay one: gainlink campaign show {out} --run {worst[0][1]} --report REPORT_DIR")
    if traced is not None and traced.drawn.draws is not None:
        lines.append(
            f'  traces stored: the {int(traced.mask.sum())} runs the envelopes draw (traces = "all" stores every '
            "run's; campaign show --run replays any run)"
        )
    pngs = " envelopes.png, scatter.png," if plots else ""
    lines.append(f"  report: {out / 'campaign.json'}, campaign.csv,{pngs} failures.txt")
    return "\n".join(lines) + "\n"


def _model_lines(tally: Tally) -> list[str]:
    """The model mismatch over the runs (gainlink.hil.loop.model_twin): largest, and how many runs it flagged."""
    if tally.model is None:
        return []
    worst, index, run_id = tally.model
    return [
        f"  model mismatch (plant against the design's model): largest {worst:.3g} of an output's range "
        f"(run {index} {run_id}); {tally.flagged} run(s) above the warning threshold"
    ]


def envelope_figure(
    plan: CampaignPlan, status: dict[str, str], store: Any, traced: Traced | None = None
) -> EnvelopeFigure:
    """``envelopes.png``'s data: percentile envelopes of outputs and commands over time across the runs ``status``
    (id -> ``pass`` or ``fail``, in plan order) of the most common trace length: at most :data:`ENVELOPE_RUNS` of
    them, each grid point's first draws (:func:`envelope_runs`; those of the plan's ``traced`` runs when given), and
    the median of the failed runs among them (:func:`envelope_bands`)."""
    sig = _signals(plan)
    bands = envelope_bands(store, status, traced=traced)
    units = dict(sig.get("units", {}))
    return EnvelopeFigure(plan.campaign.name, bands, tuple(sig["outputs"]), tuple(sig["inputs"]), units)


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


def _iae_unit(sig: dict) -> str:
    """`` [unit time]`` of an IAE when every tracked output has the same unit, else nothing."""
    units = sig.get("units", {})
    tracked = {units.get(r[2:]) for r in sig.get("references", [])}
    if len(tracked) != 1 or None in tracked:
        return ""
    return f" [{tracked.pop()} {units.get('time', 's')}]"


def _signals(plan: CampaignPlan) -> dict:
    for data in plan.artifacts.values():
        return json.loads(data)["signals"]
    return {"outputs": [], "inputs": []}


def scatter_runs(fail: np.ndarray, cap: int | None = None) -> dict[str, tuple[np.ndarray, int]]:
    """The runs the scatter plot draws of its runs (``fail``: whether each failed, in plan order), by status
    (``"fail"``, ``"pass"``): each status's runs every k-th in plan order, k the smallest step that keeps them at most
    ``cap`` (default :data:`SCATTER_RUNS`; all of them when they are that few: :func:`every_kth`); each status's
    indices into the runs and its k. (The scatter reads no trace: no row group to spare, as the envelopes'
    :func:`envelope_runs` spares them.)"""
    cap = SCATTER_RUNS if cap is None else cap
    return {status: every_kth(np.flatnonzero(fail == (status == "fail")), cap) for status in ("fail", "pass")}


def _scatter_scope(fail: np.ndarray, drawn: dict[str, tuple[np.ndarray, int]]) -> str:
    """What the scatter plot leaves out, for its title: nothing when it draws every run."""
    parts = []
    for status, word in (("pass", "passed"), ("fail", "failed")):
        runs, every = drawn[status]
        if every > 1:
            of = int((fail == (status == "fail")).sum())
            parts.append(f"{len(runs)} of {of} {word}, every {ordinal(every)} in plan order")
    return "" if not parts else "\ndrawn: " + "; ".join(parts)


def scatter_figure(plan: CampaignPlan, tally: Tally) -> ScatterFigure:
    """``scatter.png``'s data: the IAE of each run against each numeric axis, failed runs marked (at most
    :data:`SCATTER_RUNS` of each status drawn: :func:`scatter_runs`)."""
    names = [name for name in tally.axes if tally.numeric[name]]
    iae, fail = tally.scatter_iae, tally.scatter_fail
    drawn = scatter_runs(fail)
    shown = {status: runs for status, (runs, _) in drawn.items()}
    log_scale = bool(iae.size and iae.min() > 0 and iae.max() > 20 * iae.min())
    count = {"fail": int(fail.sum()), "pass": int((~fail).sum())}
    panels = []
    for name in names or [None]:
        if name is None or not iae.size:
            empty = "no numeric axis" if name is None else "no finished run"
            panels.append(ScatterPanel(name, {}, {}, count, empty=empty))
            continue
        x = tally.scatter[name]
        xs, ys = {s: x[k] for s, k in shown.items()}, {s: iae[k] for s, k in shown.items()}
        panels.append(ScatterPanel(name, xs, ys, count, log_scale))
    ylabel = "IAE (sum over tracked outputs)" + _iae_unit(_signals(plan))
    return ScatterFigure(plan.campaign.name, tuple(panels), ylabel, _scatter_scope(fail, drawn))


def _criteria_doc(c: Any) -> dict:
    return {k: (dict(v) if isinstance(v, dict) else v) for k, v in c.__dict__.items()}


def _campaign_doc(c: Any) -> dict:
    return {
        "name": c.name,
        "kind": c.kind,
        "seed": c.seed,
        "runs_per_point": c.runs,
        "description": c.description,
        "axes": describe_axes(c),
        "criteria": _criteria_doc(c.criteria),
        "spec": str(c.spec_path) if c.spec_path else None,
        "artifact": str(c.artifact_path) if c.artifact_path else None,
        "traces": c.traces,
    }


PLOTS = ("envelopes.png", "scatter.png")


def _stream_rows(plan: CampaignPlan, store: Any, csv_out: IO[str]) -> Tally:
    """Write every row, in plan order, to ``campaign.csv`` (``csv_out``), counting each into the returned
    :class:`Tally`: a chunk of runs at a time, each row's text joined from its head's (:func:`~.rows.head_texts`: the
    plan's, made a chunk at a time) and its verdict's spilled texts (:class:`~.rows.Verdicts`), nothing decoded again
    and no row built value by value."""
    ids = plan_ids(plan)
    verdicts = Verdicts(store, plan.campaign.criteria, ids)
    try:
        tally = Tally(plan, verdicts)
        tracked, outs = sorted(verdicts.tracked), sorted(verdicts.outputs)
        csv.writer(csv_out, lineterminator="\n").writerow(csv_head(plan, verdicts.tracked, verdicts.outputs))
        start = 0
        for pre, mid, post in head_texts(plan, _axes(plan)):
            slots = verdicts.slot[start : start + len(pre)].tolist()
            status, cells = verdicts.rows(slots, tracked, outs)
            csv_out.write("".join([a + b + c + d + e for a, b, c, d, e in zip(pre, status, mid, cells, post)]))
            start += len(pre)
        tally.finish(ids)
        return tally
    finally:
        verdicts.close()


def merge(
    plan: CampaignPlan, store: Any, *, plots: bool = True, draw: Callable[[Figure], Any] | None = None
) -> tuple[str, StoredRows, Counter]:
    """Merge the stored runs into the report files; returns the summary text, the rows (made from the store when
    asked, :class:`~.stored_rows.StoredRows`) and the count of runs by status.

    Streamed: the rows are written to ``campaign.csv`` a chunk at a time (through a temporary file and a rename),
    ``campaign.json`` holds the campaign, the counts, the grid points and the failures (not every run: its whole row
    is the store's, :class:`~.stored_rows.StoredRows`, ``gainlink campaign show --run``), and the summary, failures
    and plots are drawn from a :class:`~.rows.Tally`. Without ``plots``, the PNGs are not drawn (about a second per
    merge) and those of an earlier merge are removed: a report never shows plots of other runs than its own.

    ``draw``: where the figures are drawn (:func:`drawn_figures`), here when None."""
    with atomic_writer(store.out / "campaign.csv") as csv_out:
        tally = _stream_rows(plan, store, csv_out)
    traced = traced_runs(plan)
    pngs = drawn_figures(plan, tally, store, traced, draw) if plots else {}
    points = tally.point_list()
    doc = {
        "campaign": _campaign_doc(plan.campaign),
        "counts": {"runs": tally.runs, **{k: tally.counts.get(k, 0) for k in ("pass", "fail", "error", "missing")}},
        "points": points,
        "failures": tally.failure_rows(),
        "failures_limit": FAILURES_LIMIT,
    }
    stored = traced if plan.campaign.traces == "drawn" else None
    summary = summary_text(plan, tally, points, out=store.out, plots=plots, traced=stored)
    files: dict[str, bytes | str] = {
        "campaign.json": json.dumps(doc, sort_keys=True, indent=1, allow_nan=False) + "\n",
        "failures.txt": failures_text(tally),
        "summary.txt": summary,
    }
    if not plots:
        for name in PLOTS:
            (store.out / name).unlink(missing_ok=True)
    files.update((name, png()) for name, png in pngs.items())
    publish_files(store.out, files)
    return summary, StoredRows(plan, store), tally.counts


def drawn_figures(
    plan: CampaignPlan, tally: Tally, store: Any, traced: Traced, draw: Callable[[Figure], Any] | None
) -> dict[str, Callable[[], bytes]]:
    """The report's PNGs by name, each as the call that gives its bytes. Each figure's data is gathered here, the
    scatter's first; ``draw`` (a cluster's ``submit`` of :func:`~.figures.png_of`, say: any call returning something
    whose ``result()`` is the PNG) draws each elsewhere meanwhile, so the scatter is drawn while the
    envelopes' bands are read here and both figures are drawn at once on two workers. A figure ``draw`` fails to give
    is drawn here, said in the log; without ``draw`` each is drawn here."""
    figures: dict[str, Figure] = {}
    pending: dict[str, Any] = {}
    for name, gather in (
        ("scatter.png", lambda: scatter_figure(plan, tally)),
        ("envelopes.png", lambda: envelope_figure(plan, tally.status, store, traced)),
    ):
        figures[name] = gather()
        if draw is not None:
            pending[name] = draw(figures[name])
    return {name: partial(_png, name, figures[name], pending.get(name)) for name in PLOTS}


def _png(name: str, figure: Figure, drawing: Any | None) -> bytes:
    """``figure``'s PNG: ``drawing``'s result when it gives one, else drawn here (a failed drawing said in the log)."""
    if drawing is None:
        return figure.png()
    try:
        png = drawing.result()
    except Exception as exc:  # a dead worker, a cluster gone: the figure is still the report's
        why = f"{type(exc).__name__}: {exc}"
    else:
        if isinstance(png, bytes):
            return png
        why = f"it gave {type(png).__name__}, not the PNG's bytes"
    log.warning("%s could not be drawn on the cluster (%s); drawn here", name, why)
    return figure.png()
