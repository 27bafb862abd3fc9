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
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import IO, Any, Protocol

import numpy as np
from gainlink.fileio import atomic_writer, publish_files

from .block_layout import MEASURE_CELLS, METRIC_CELLS
from .envelopes import EnvelopeRequest, Traced, envelope_bands, envelope_request, every_kth, traced_runs
from .figures import EnvelopeFigure, Figure, ScatterFigure, ScatterPanel, ordinal
from .plan import CampaignPlan, describe_axes
from .rows import FAILURES_LIMIT, Tally, Verdicts, head_texts, plan_ids
from .stored_rows import StoredRows

log = logging.getLogger(__name__)

MAX_POINT_LINES = 30
#: The most runs of each status (passed, failed) the scatter plot draws (:func:`scatter_runs`): a run drawn costs the
#: figure ~10 µs of CPU in the shipped pendulum's three panels, and a few thousand show the cloud as all of them do.
SCATTER_RUNS = 2000


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
    """``envelopes.png``'s data: percentiles of outputs and commands over time across the runs ``status``
    (id -> ``pass`` or ``fail``, in plan order) of the most common trace length: at most
    :data:`~.envelopes.ENVELOPE_RUNS` of them, each grid point's first draws (:func:`~.envelopes.envelope_runs`; those
    of the plan's ``traced`` runs when given), and the median of the failed runs among them
    (:func:`~.envelopes.envelope_bands`)."""
    return replace(envelope_template(plan), bands=envelope_bands(store, status, traced=traced))


def envelope_template(plan: CampaignPlan) -> EnvelopeFigure:
    """``envelopes.png``'s data but its bands (``None``): the campaign's name, its signals' names and units."""
    sig = _signals(plan)
    units = dict(sig.get("units", {}))
    return EnvelopeFigure(plan.campaign.name, None, tuple(sig["outputs"]), tuple(sig["inputs"]), units)


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


def _write_rows(plan: CampaignPlan, verdicts: Verdicts, csv_out: IO[str]) -> None:
    """Write every row, in plan order, to ``campaign.csv`` (``csv_out``): a chunk of runs at a time, each row's text
    joined from its head's (:func:`~.rows.head_texts`: the plan's, made a chunk at a time) and its verdict's spilled
    texts (:class:`~.rows.Verdicts`), nothing decoded again and no row built value by value."""
    tracked, outs = sorted(verdicts.tracked), sorted(verdicts.outputs)
    csv.writer(csv_out, lineterminator="\n").writerow(csv_head(plan, verdicts.tracked, verdicts.outputs))
    start = 0
    for pre, mid, post in head_texts(plan, _axes(plan)):
        slots = verdicts.slot[start : start + len(pre)].tolist()
        status, cells = verdicts.rows(slots, tracked, outs)
        csv_out.write("".join([a + b + c + d + e for a, b, c, d, e in zip(pre, status, mid, cells, post)]))
        start += len(pre)


def tallied(plan: CampaignPlan, verdicts: Verdicts) -> Tally:
    """The :class:`~.rows.Tally` of the plan's runs, judged by ``verdicts`` (made for :func:`~.rows.plan_ids`)."""
    tally = Tally(plan, verdicts)
    tally.finish(plan_ids(plan))
    return tally


class Drawing(Protocol):
    """Where the report's figures are made besides here (a cluster: the runner's), each call giving at once something
    whose ``result()`` is what was asked (a Dask future, say)."""

    def draw(self, figure: Figure) -> Any:
        """``figure``'s PNG (:func:`~.figures.png_of`)."""

    def read_stack(self, ids: np.ndarray) -> Any:
        """The envelopes' stack of the runs ``ids`` (:func:`~.envelopes.cluster_stack`; ``None``: not read there)."""

    def stack_png(self, stack: Any, request: EnvelopeRequest, figure: EnvelopeFigure) -> Any:
        """``envelopes.png`` of ``stack`` (what :meth:`read_stack` gave) and the verdicts' ``request``
        (:func:`~.envelopes.stack_png`; ``None``: no stack there)."""


def merge(
    plan: CampaignPlan,
    store: Any,
    *,
    plots: bool = True,
    drawing: Drawing | None = None,
    verdicts: Verdicts | None = None,
) -> tuple[str, StoredRows, Counter]:
    """Merge the stored runs into the report files; returns the summary text, the rows (made from the store when
    asked, :class:`~.stored_rows.StoredRows`) and the count of runs by status.

    Streamed: the rows are written to ``campaign.csv`` a chunk at a time (through a temporary file and a rename),
    ``campaign.json`` holds the campaign, the counts, the grid points and the failures (not every run: its whole row
    is the store's, :class:`~.stored_rows.StoredRows`, ``gainlink campaign show --run``), and the summary, failures
    and plots are drawn from a :class:`~.rows.Tally`. Without ``plots``, the PNGs are not drawn (about a second per
    merge) and those of an earlier merge are removed: a report never shows plots of other runs than its own.

    ``drawing``: where the figures are made besides here (:func:`drawn_figures`): the envelopes' traces are read there
    from the start, while the runs are judged here, and the rows are written here while the figures are drawn.

    ``verdicts``: the plan's, holding those of the blocks judged ahead (by the workers that ran them, as the campaign
    ran: :meth:`~.rows.Verdicts.add`); the other stored runs are judged here. Closed here, as verdicts made here are."""
    traced = traced_runs(plan)
    stack = drawing.read_stack(traced.ids) if plots and drawing is not None else None
    verdicts = Verdicts(plan.campaign.criteria, plan_ids(plan)) if verdicts is None else verdicts
    try:
        verdicts.complete(store)
        tally = tallied(plan, verdicts)
        pngs = drawn_figures(plan, tally, store, traced, drawing, stack) if plots else {}
        with atomic_writer(store.out / "campaign.csv") as csv_out:
            _write_rows(plan, verdicts, csv_out)
    finally:
        verdicts.close()
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
    plan: CampaignPlan, tally: Tally, store: Any, traced: Traced, drawing: Drawing | None, stack: Any = None
) -> dict[str, Callable[[], bytes]]:
    """The report's PNGs by name, each as the call that gives its bytes. Without ``drawing`` each figure's data is
    gathered here and drawn here. With it the scatter's data is gathered here and drawn there; the envelopes', given
    the ``stack`` :meth:`Drawing.read_stack` is reading, are made there from it (:meth:`Drawing.stack_png`: the bands
    of a cluster's worker that read the traces while the runs were judged here), else gathered here and drawn there.
    A figure ``drawing`` fails to give is made here, said in the log (a stack not read there, made here quietly)."""
    scatter = scatter_figure(plan, tally)
    envelopes = partial(envelope_figure, plan, tally.status, store, traced)
    if drawing is None:
        return {"envelopes.png": lambda: envelopes().png(), "scatter.png": scatter.png}
    pending = {"scatter.png": drawing.draw(scatter)}
    if stack is not None:
        pending["envelopes.png"] = drawing.stack_png(stack, envelope_request(tally.status, traced=traced),
                                                     envelope_template(plan))  # fmt: skip
    else:
        figure = envelopes()
        envelopes, pending["envelopes.png"] = (lambda: figure), drawing.draw(figure)
    gathered = {"envelopes.png": envelopes, "scatter.png": lambda: scatter}
    return {name: partial(_png, name, gathered[name], pending[name]) for name in PLOTS}


def _png(name: str, gather: Callable[[], Figure], drawing: Any) -> bytes:
    """A figure's PNG: ``drawing``'s result when it gives one, else its data ``gather``-ed and drawn here (a failed
    drawing said in the log; ``None``, a stack not read there, not)."""
    try:
        png = drawing.result()
    except Exception as exc:  # a dead worker, a cluster gone: the figure is still the report's
        why = f"{type(exc).__name__}: {exc}"
    else:
        if isinstance(png, bytes):
            return png
        if png is None:
            return gather().png()
        why = f"it gave {type(png).__name__}, not the PNG's bytes"
    log.warning("%s could not be drawn on the cluster (%s); drawn here", name, why)
    return gather().png()
