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
    stable, why, ratios = bool(result.complete and finite), result.reason, {}
    if stable:
        for name, e in _errors(tr, artifact).items():
            ok, ratio = growth(e)
            ratios[name] = ratio
            if not ok:
                stable, why = False, f"{name} error grows at the end (last/third quarter peak {ratio:.3g})"
    elif why is None:
        why = "non-finite output"
    sat = tr.sat.any(axis=1) if tr.sat.size else np.zeros(0, bool)
    outs = artifact.signals["outputs"]
    out = {
        "stable": stable,
        "unstable_reason": None if stable else why,
        "growth_ratio": ratios,
        "output_min": {n: float(np.nanmin(tr.y[:, i])) for i, n in enumerate(outs)} if tr.y.size else {},
        "output_max": {n: float(np.nanmax(tr.y[:, i])) for i, n in enumerate(outs)} if tr.y.size else {},
        "longest_saturation_s": _longest_true(sat) * artifact.Ts,
    }
    twin = result.metrics.get("twin")  # gainlink.proof.twin.twin_comparison of the run and its float64 twin
    if isinstance(twin, dict):
        out["twin_output_deviation"] = twin.get("worst_dy_rel")
        out["twin_command_deviation"] = twin.get("worst_du_rel")
    model = result.metrics.get("model_twin")  # gainlink.hil.loop.model_twin: the plant against the design's model
    if isinstance(model, dict):
        out["model_mismatch"] = model.get("worst")
        ratios = [v.get("ratio") for v in model.get("iae", {}).values() if v.get("ratio") is not None]
        out["model_iae_ratio"] = max(ratios, key=lambda x: abs(np.log(x)) if x > 0 else np.inf, default=None)
        out["model_warning"] = bool(model.get("warning"))
    return _clean(out)


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


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
