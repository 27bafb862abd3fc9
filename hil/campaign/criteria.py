"""Pass/fail of one campaign run: the quantities measured on the worker, and the verdict from the criteria.

The worker reduces a run to what the criteria read (:func:`measure`), so a campaign's criteria can be
changed and the report merged again without running anything twice (:func:`evaluate`):

- ``stable``: the run completed with finite outputs and its tracked errors (``r - Ci y``; every output
  against zero without integral action) do not grow at the end: the peak ``|e|`` over the last quarter
  of the run is at most 1.05 times the peak over the third quarter, or below 2 % of the largest ``|e|``
  of the run (a decaying or steady oscillation is stable but does not settle; a growing one is not);
- ``bounds``: every named output stays within ``[low, high]`` for the whole run;
- ``settled_within``, ``overshoot_below``, ``iae_below``: each tracked output's settling time (2 % band
  after the last reference change; never settled fails), overshoot (%) and IAE, as in the HIL report;
- ``saturated_at_most``: the longest stretch of consecutive samples with any command saturated, in s;
- ``twin_deviation_below``: the largest deviation of an output from the float64 closed-loop twin's, relative
  to the twin's excursion (``worst_dy_rel`` of :func:`gainlink.proof.twin.twin_comparison`, which the run's metrics
  carry as ``twin``): what float32, the link and the faults cost the loop.

Every run also records its model mismatch (``model_mismatch``: the largest output deviation from the model twin,
relative to the output's range; ``model_iae_ratio``: the tracked IAE of the plant over the model twin's, the one
farthest from 1; ``model_warning``), from :mod:`gainlink.hil.loop.model_twin`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .config import Criteria

GROWTH = 1.05
FLOOR = 0.02


def _longest_true(mask: np.ndarray) -> int:
    """Length of the longest run of True in a 1-D boolean array."""
    if not mask.any():
        return 0
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return int((stops - starts).max())


def _errors(trace: Any, artifact: Any) -> dict[str, np.ndarray]:
    if artifact.q:
        return {name: trace.r[:, j] - trace.y @ artifact.Ci[j] for j, name in enumerate(artifact.signals["references"])}
    return {name: -trace.y[:, i] for i, name in enumerate(artifact.signals["outputs"])}


def growth(e: np.ndarray) -> tuple[bool, float | None]:
    """Whether an error signal does not grow at the end (see the module docstring), and the ratio."""
    N = e.size
    if N < 8:
        return True, None
    a = np.abs(e)
    last, third = float(a[3 * N // 4 :].max()), float(a[N // 2 : 3 * N // 4].max())
    ratio = last / third if third > 0 else (0.0 if last == 0 else float("inf"))
    return bool(last <= GROWTH * third or last <= FLOOR * float(a.max())), ratio


def measure(result: Any, artifact: Any) -> dict:
    """What the criteria read from a run (JSON-able; NaN and infinity become ``None``)."""
    tr = result.trace
    finite = bool(np.all(np.isfinite(tr.y)))
    grew = {k: growth(e) for k, e in _errors(tr, artifact).items()} if (result.complete and finite) else {}
    sat = tr.sat.any(axis=1) if tr.sat.size else np.zeros(0, bool)
    with warnings.catch_warnings():  # an output all NaN: nanmin's NaN (None in the row), not a warning a run
        warnings.simplefilter("ignore", RuntimeWarning)
        low = [_num(float(np.nanmin(tr.y[:, i]))) for i in range(tr.y.shape[1])] if tr.y.size else []
        high = [_num(float(np.nanmax(tr.y[:, i]))) for i in range(tr.y.shape[1])] if tr.y.size else []
    return _measured(result, artifact, finite=finite, grew=grew, low=low, high=high, longest=_longest_true(sat))


def measure_block(results: list, artifact: Any) -> list[dict]:
    """:func:`measure` of each of ``results`` (a campaign block's runs), each figure taken as a column over the
    block's runs of one length (their ``(runs, steps, ...)`` arrays, :data:`~..loop.block_metrics.RUNS_AT_ONCE` runs
    at a time): the same dicts, every number bit for bit (extrema and counts have no order, and ``np.nanmin`` of an
    array is ``np.fmin.reduce`` of it; the growth ratios are the same IEEE operations on them; the tracked errors'
    products ``y @ Ci[j]`` are taken run by run, the call a run alone makes, their differences from the references
    over the block). A run of no steps takes :func:`measure` itself."""
    from ..loop.block_metrics import runs_at_once

    out: list[dict | None] = [None] * len(results)
    lengths: dict[int, list[int]] = {}
    for i, result in enumerate(results):
        lengths.setdefault(int(result.trace.y.shape[0]), []).append(i)
    for n, idx in lengths.items():
        if n == 0:
            for i in idx:
                out[i] = measure(results[i], artifact)
            continue
        for part in runs_at_once(idx):
            group = [results[i] for i in part]
            for i, measured in zip(part, _measured_group(group, artifact, n=n)):
                out[i] = measured
    return out  # type: ignore[return-value]


def _measured_group(results: list, artifact: Any, *, n: int) -> list[dict]:
    """:func:`measure` of runs of one length ``n`` > 0, from their columns."""
    from ..loop.block_metrics import finite_lists, stacked

    traces = [r.trace for r in results]
    Y = stacked([tr.y for tr in traces])
    finite = np.isfinite(Y).all(axis=(1, 2)).tolist()
    grew = _growth_columns(_error_columns(traces, artifact, Y=Y), n)
    sat = stacked([tr.sat for tr in traces])
    longest = _longest_columns(sat.any(axis=2) if sat.shape[2] else np.zeros(sat.shape[:2], bool))
    low = finite_lists(np.stack([np.fmin.reduce(Y[:, :, i], axis=1) for i in range(Y.shape[2])], axis=1))
    high = finite_lists(np.stack([np.fmax.reduce(Y[:, :, i], axis=1) for i in range(Y.shape[2])], axis=1))
    out = []
    for j, result in enumerate(results):
        mine = {k: g[j] for k, g in grew.items()} if (result.complete and finite[j]) else {}
        out.append(_measured(result, artifact, finite=finite[j], grew=mine, low=low[j], high=high[j],
                             longest=longest[j]))  # fmt: skip
    return out


def _error_columns(traces: list, artifact: Any, *, Y: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`_errors` of each of ``traces`` (runs of one length, their outputs ``Y`` stacked) as (runs, steps)
    columns, one per tracked signal: each run's product ``y @ Ci[j]`` made as it is alone, the differences from the
    references taken over the runs (the same subtraction)."""
    from ..loop.block_metrics import stacked

    if not artifact.q:
        return {name: -Y[:, :, i] for i, name in enumerate(artifact.signals["outputs"])}
    R = stacked([tr.r for tr in traces])
    return {name: R[:, :, j] - np.stack([tr.y @ artifact.Ci[j] for tr in traces])
            for j, name in enumerate(artifact.signals["references"])}  # fmt: skip


def _growth_columns(errors: dict[str, np.ndarray], n: int) -> dict[str, list[tuple[bool, float | None]]]:
    """:func:`growth` of each row of each (runs, ``n``) error column: per signal, per run, ``(ok, ratio)``."""
    out = {}
    for name, E in errors.items():
        if n < 8:
            out[name] = [(True, None)] * E.shape[0]
            continue
        A = np.abs(E)
        last, third, peak = A[:, 3 * n // 4 :].max(axis=1), A[:, n // 2 : 3 * n // 4].max(axis=1), A.max(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(third > 0, last / third, np.where(last == 0, 0.0, np.inf))
        ok = (last <= GROWTH * third) | (last <= FLOOR * peak)
        out[name] = list(zip(ok.tolist(), ratio.tolist()))
    return out


def _longest_columns(mask: np.ndarray) -> list[int]:
    """:func:`_longest_true` of each row of ``mask`` (runs, steps): the step less the last False at or before it is
    the stretch of True ending there."""
    steps = np.arange(mask.shape[1])
    last_false = np.maximum.accumulate(np.where(mask, -1, steps), axis=1)
    return (steps - last_false).max(axis=1).tolist() if mask.shape[1] else [0] * mask.shape[0]


def _measured(result: Any, artifact: Any, *, finite: bool, grew: dict, low: list, high: list, longest: int) -> dict:
    """:func:`measure`'s dict from a run's figures: ``grew`` its tracked errors' :func:`growth` (empty unless it
    completed with finite outputs), ``low``/``high`` its outputs' NaN-ignoring extrema (non-finite ones None),
    ``longest`` its longest stretch of saturated steps; every number made JSON-able as it is put in (:func:`_num`)."""
    stable, why, ratios = bool(result.complete and finite), result.reason, {}
    if stable:
        for name, (ok, ratio) in grew.items():
            ratios[name] = _num(ratio)
            if not ok:
                stable, why = False, f"{name} error grows at the end (last/third quarter peak {ratio:.3g})"
    elif why is None:
        why = "non-finite output"
    outs = artifact.signals["outputs"]
    out = {
        "stable": stable,
        "unstable_reason": None if stable else why,
        "growth_ratio": ratios,
        "output_min": dict(zip(outs, low)),
        "output_max": dict(zip(outs, high)),
        "longest_saturation_s": _num(longest * artifact.Ts),
    }
    twin = result.metrics.get("twin")  # gainlink.proof.twin.twin_comparison of the run and its float64 twin
    if isinstance(twin, dict):
        out["twin_output_deviation"] = _clean(twin.get("worst_dy_rel"))
        out["twin_command_deviation"] = _clean(twin.get("worst_du_rel"))
    model = result.metrics.get("model_twin")  # gainlink.hil.loop.model_twin: the plant against the design's model
    if isinstance(model, dict):
        out["model_mismatch"] = _clean(model.get("worst"))
        ratios = [v.get("ratio") for v in model.get("iae", {}).values() if v.get("ratio") is not None]
        out["model_iae_ratio"] = _clean(max(ratios, key=lambda x: abs(np.log(x)) if x > 0 else np.inf, default=None))
        out["model_warning"] = bool(model.get("warning"))
    return out


def _num(x: Any) -> Any:
    """``x``, None when it is a float that is not finite (``math.isfinite``: a Python float's test without numpy's
    per-call cost)."""
    return None if isinstance(x, float) and not math.isfinite(x) else x


def _clean(obj: Any) -> Any:
    """``obj`` with every non-finite float (at any depth of its dicts) None."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    return _num(obj)


def evaluate(criteria: Criteria, record: dict) -> list[tuple[str, str]]:
    """The criteria a finished run fails, as (criterion, one short phrase) pairs (empty: the run passes)."""
    m, q = record["metrics"], record["measures"]
    failed = []
    if criteria.stable and not q["stable"]:
        failed.append(("stable", f"unstable: {q['unstable_reason']}"))
    for name, (lo, hi) in criteria.bounds.items():
        low, high = q["output_min"].get(name), q["output_max"].get(name)
        if low is None or high is None:
            failed.append(("bounds", f"{name} not finite"))
        elif low < lo or high > hi:
            failed.append(("bounds", f"{name} left [{lo:g}, {hi:g}] (min {low:.3g}, max {high:.3g})"))
    for name, tr in m.get("tracked", {}).items():
        if criteria.settled_within is not None:
            ts = tr.get("settling_time_s")
            if ts is None or ts > criteria.settled_within:
                failed.append(
                    (
                        "settled_within",
                        f"{name} "
                        + ("never settled" if ts is None else f"settled in {ts:.3g} s")
                        + f" > {criteria.settled_within:g} s",
                    )
                )
        if criteria.overshoot_below is not None and (tr.get("overshoot_pct") or 0.0) >= criteria.overshoot_below:
            failed.append(
                ("overshoot_below", f"{name} overshoot {tr['overshoot_pct']:.3g}% >= {criteria.overshoot_below:g}%")
            )
        if criteria.iae_below is not None:
            iae = tr.get("iae")
            if iae is None or iae >= criteria.iae_below:
                failed.append(
                    ("iae_below", f"{name} IAE {iae if iae is None else f'{iae:.3g}'} >= {criteria.iae_below:g}")
                )
    if criteria.saturated_at_most is not None and q["longest_saturation_s"] > criteria.saturated_at_most:
        failed.append(
            ("saturated_at_most", f"saturated {q['longest_saturation_s']:.3g} s > {criteria.saturated_at_most:g} s")
        )
    if criteria.twin_deviation_below is not None:
        dev = q.get("twin_output_deviation")
        if dev is None or dev >= criteria.twin_deviation_below:
            failed.append(
                (
                    "twin_deviation_below",
                    f"twin deviation {dev if dev is None else f'{dev:.3g}'} >= {criteria.twin_deviation_below:g}",
                )
            )
    return failed


@dataclass(frozen=True)
class RunColumns:
    """What :func:`evaluate` reads of many finished runs, one entry a run: a number is NaN where the run's record holds
    ``None`` or lacks it (a stored number is never NaN: a measure or metric that is not finite is stored ``None``).

    ``tracked`` maps each tracked output some run has to its :data:`~.rows.METRIC_CELLS` arrays and ``present``
    (whether the run has that output: it is judged on the outputs it has)."""

    stable: np.ndarray  # bool: True where the record says so
    unstable_reason: list  # str or None
    longest_saturation_s: np.ndarray
    twin_output_deviation: np.ndarray
    output_min: dict[str, np.ndarray]
    output_max: dict[str, np.ndarray]
    tracked: dict[str, dict[str, np.ndarray]]


def evaluate_columns(criteria: Criteria, runs: RunColumns) -> list[list[tuple[str, str]]]:
    """:func:`evaluate` of every run of ``runs`` at once: the same criteria in the same order with the same phrases,
    each criterion a comparison over the columns and a phrase made for the runs that fail it only."""
    failed: list[list[tuple[str, str]]] = [[] for _ in range(len(runs.stable))]

    def note(name: str, mask: np.ndarray, phrase: Any) -> None:
        for i in np.flatnonzero(mask).tolist():
            failed[i].append((name, phrase(i)))

    if criteria.stable:
        note("stable", ~runs.stable, lambda i: f"unstable: {runs.unstable_reason[i]}")
    for name, (lo, hi) in criteria.bounds.items():
        _bounds(name, lo, hi, runs, note)
    for name in sorted(runs.tracked):
        _tracked(criteria, name, runs.tracked[name], note)
    if criteria.saturated_at_most is not None:
        sat, most = runs.longest_saturation_s, criteria.saturated_at_most
        note("saturated_at_most", sat > most, lambda i: f"saturated {sat[i]:.3g} s > {most:g} s")
    if criteria.twin_deviation_below is not None:
        dev, below = runs.twin_output_deviation, criteria.twin_deviation_below
        note("twin_deviation_below", np.isnan(dev) | (dev >= below), lambda i: (
            f"twin deviation {'None' if np.isnan(dev[i]) else f'{dev[i]:.3g}'} >= {below:g}"
        ))  # fmt: skip
    return failed


def _bounds(name: str, lo: float, hi: float, runs: RunColumns, note: Any) -> None:
    """The bounds criterion on output ``name`` of :func:`evaluate_columns`."""
    nan = np.full(len(runs.stable), np.nan)
    low, high = runs.output_min.get(name, nan), runs.output_max.get(name, nan)
    lost = np.isnan(low) | np.isnan(high)
    note("bounds", lost | (low < lo) | (high > hi), lambda i: (
        f"{name} not finite" if lost[i] else f"{name} left [{lo:g}, {hi:g}] (min {low[i]:.3g}, max {high[i]:.3g})"
    ))  # fmt: skip


def _tracked(criteria: Criteria, name: str, tr: dict[str, np.ndarray], note: Any) -> None:
    """The criteria on tracked output ``name`` (``tr``: its columns) of :func:`evaluate_columns`, in its order."""
    present = tr["present"]
    if criteria.settled_within is not None:
        ts, within = tr["settling_time_s"], criteria.settled_within
        note("settled_within", present & (np.isnan(ts) | (ts > within)), lambda i: (
            f"{name} " + ("never settled" if np.isnan(ts[i]) else f"settled in {ts[i]:.3g} s") + f" > {within:g} s"
        ))  # fmt: skip
    if criteria.overshoot_below is not None:
        over, below = tr["overshoot_pct"], criteria.overshoot_below
        note("overshoot_below", present & (np.nan_to_num(over, nan=0.0) >= below),
             lambda i: f"{name} overshoot {over[i]:.3g}% >= {below:g}%")  # fmt: skip
    if criteria.iae_below is not None:
        iae, below = tr["iae"], criteria.iae_below
        note("iae_below", present & (np.isnan(iae) | (iae >= below)), lambda i: (
            f"{name} IAE {'None' if np.isnan(iae[i]) else f'{iae[i]:.3g}'} >= {below:g}"
        ))  # fmt: skip
