"""A campaign block's metrics as columns: :func:`~.metrics.compute_metrics` of every run, each figure one
reduction over the block's (runs, steps, ...) arrays instead of one per run.

The runs of one length are stacked and reduced along their steps; each run's dict is made from the columns at the
end, in the order and form :func:`~.metrics.compute_metrics` gives it, the same numbers bit for bit: the counts,
extrema and fractions do not depend on the order they are taken in, a row's sum along its contiguous steps is
numpy's pairwise sum of that row alone (as the run's own ``np.sum``), and the elementwise steps are the same IEEE
operations. The products with the design's matrices (the tracked outputs ``y @ Ci[j]``, the twin's integral command
``z @ Ki.T``) are taken run by run, the call a run alone makes on the same arrays: a BLAS kernel may round another
shape differently. What a block rarely has is left to the per-run functions: a run of no steps, the model twin.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gainlink.laws import flags

from .lockstep import address
from .metrics import RunTrace, _clean, compute_metrics
from .model_twin import model_mismatch

BAND = 0.02  # the settling band of :func:`~.metrics.tracking`


def block_metrics(traces: list[RunTrace], *, artifact: Any, mode: str, late: int, period_s: list[float],
                  model_start: list[str], timed: list[dict]) -> list[dict]:  # fmt: skip
    """:func:`~.metrics.compute_metrics` of each of ``traces`` (with its ``period_s``, ``model_start`` and ``timed``),
    computed as columns over the traces of each length (module docstring)."""
    out: list[dict | None] = [None] * len(traces)
    cleaned: dict[int, dict] = {}
    for t in timed:  # once per dict: the runs of one length share theirs
        if id(t) not in cleaned:
            cleaned[id(t)] = _clean(t)
    lengths: dict[int, list[int]] = {}
    for i, tr in enumerate(traces):
        lengths.setdefault(int(tr.t.size), []).append(i)
    for n, idx in lengths.items():
        if n == 0:  # nothing to reduce: the run's own function
            for i in idx:
                out[i] = compute_metrics(traces[i], artifact=artifact, mode=mode, late=late, period_s=period_s[i],
                                         model_start=model_start[i], timed=timed[i])  # fmt: skip
            continue
        rows = _group([traces[i] for i in idx], artifact=artifact)
        for j, i in enumerate(idx):
            out[i] = _metrics_of(j, rows, traces[i], artifact=artifact, late=late, period_s=period_s[i],
                                 model_start=model_start[i], timed=cleaned[id(timed[i])])  # fmt: skip
    return out  # type: ignore[return-value]


def stacked(arrays: list[np.ndarray]) -> np.ndarray:
    """The runs' arrays of one shape as one (runs, ...) array: a read-only view when they are one array (a plan's
    times or references every run of a block reads: stride 0) or lie equally spaced in one (a block's record), else
    a copy."""
    first = arrays[0]
    if all(a is first for a in arrays):
        return np.broadcast_to(first, (len(arrays), *first.shape))
    alike = first.base is not None and all(
        a.base is first.base and a.shape == first.shape and a.strides == first.strides for a in arrays
    )
    if alike and len(arrays) > 1:
        gaps = np.diff([address(a) for a in arrays])
        if (gaps == gaps[0]).all():
            view = np.lib.stride_tricks.as_strided(first, (len(arrays), *first.shape), (int(gaps[0]), *first.strides))
            view.flags.writeable = False
            return view
    return np.stack(arrays)


def _steps(reduce: str, A: np.ndarray, **kw) -> np.ndarray:
    """``A.<reduce>(axis=1, **kw)`` of ``A`` (runs, n, width), one column at a time: numpy reduces the middle axis
    of a (1000, 1000, 2) array ~7x slower than each column's steps (the same numbers: an extremum has no order)."""
    columns = [getattr(A[:, :, k], reduce)(axis=1, **kw) for k in range(A.shape[2])]
    return np.stack(columns, axis=-1) if columns else np.zeros((A.shape[0], 0))


def _count_false(A: np.ndarray) -> np.ndarray:
    """The False steps of each row of ``A`` (runs, n), counted once when the runs share one array (stride 0: a
    block's runs all answered in time)."""
    if A.strides[0] == 0:
        return np.broadcast_to(np.count_nonzero(~A[0]), A.shape[:1])
    return np.count_nonzero(~A, axis=1)


def _largest_difference(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Each run's largest ``|A - B|`` over its steps per column (runs, width), 0 when it has none: a column at a
    time (the differences of the whole (runs, n, width) arrays and their middle axis's maxima cost ~1.8x as much)."""
    columns = [np.abs(A[:, :, k] - B[:, :, k]).max(axis=1, initial=0.0) for k in range(A.shape[2])]
    return np.stack(columns, axis=-1) if columns else np.zeros((A.shape[0], 0))


def _group(traces: list[RunTrace], *, artifact: Any) -> dict:
    """The columns of runs of one length ``n`` > 0: each figure of :func:`~.metrics.compute_metrics` per run."""
    a = artifact
    Y, U = stacked([tr.y for tr in traces]), stacked([tr.u for tr in traces])
    sat = stacked([tr.sat for tr in traces])
    cols: dict[str, Any] = {
        "lost": _count_false(stacked([tr.got for tr in traces])),
        "sat_frac": sat.mean(axis=1),
        "saturated_steps": np.count_nonzero(sat.any(axis=2), axis=1),
        "sat_per_input": sat.sum(axis=1),
        "y_final": Y[:, -1],
        "u_peak": _steps("max", np.abs(U)),
        "y_peak": _steps("max", np.abs(Y)),
        "refused": np.count_nonzero(stacked([tr.flags for tr in traces]) & flags.FAULT, axis=1),
    }
    t = traces[0].t
    R = stacked([tr.r for tr in traces])
    # the tracked outputs, run by run (the product a run alone takes); a regulator's: its outputs about y_op
    if a.q:
        tracked_y = [np.stack([tr.y @ a.Ci[j] for tr in traces]) for j in range(a.q)]
        refs = [R[:, :, j] for j in range(a.q)]
    else:
        tracked_y = [Y[:, :, i] for i in range(a.p)]
        refs = [np.broadcast_to(a.y_op[i], Y.shape[:2]) for i in range(a.p)]
    cols["tracked"] = [_lists(_tracking(t, yj, rj)) for yj, rj in zip(tracked_y, refs)]
    TU = stacked([tr.twin_u for tr in traces])
    twin = np.isfinite(TU).all(axis=(1, 2))  # RunTrace.has_twin of each (n > 0 here)
    cols["has_twin"] = twin
    if twin.any():
        cols["twin"] = _lists(_twin_columns(traces, Y=Y, U=U, TU=TU, tracked_y=tracked_y, refs=refs, t=t,
                                            artifact=a))  # fmt: skip
    return _lists(cols)


def _lists(cols: dict) -> dict:
    """``cols`` with each array a list of Python numbers (or of rows): one conversion per column, not one per run."""
    return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in cols.items()}


def _twin_columns(traces: list[RunTrace], *, Y, U, TU, tracked_y, refs, t, artifact: Any) -> dict:
    """:func:`gainlink.proof.twin.twin_comparison`'s figures and the twin's integrators' peaks, per run (the rows
    of runs without a twin are computed and never read)."""
    a = artifact
    TY, TZ = stacked([tr.twin_y for tr in traces]), stacked([tr.twin_z for tr in traces])
    dt = float(t[1] - t[0]) if t.size > 1 else 0.0
    if a.q:
        twin_tracked = [np.stack([tr.twin_y @ a.Ci[j] for tr in traces]) for j in range(a.q)]
    else:
        twin_tracked = [TY[:, :, i] for i in range(a.p)]
    cols = {
        "du": _largest_difference(U, TU),
        "dy": _largest_difference(Y, TY),
        "excursion": _steps("max", TY) - _steps("min", TY),
        "iae_real": [(np.sum(np.abs(r - y), axis=1) * dt).tolist() for y, r in zip(tracked_y, refs)],
        "iae_twin": [(np.sum(np.abs(r - y), axis=1) * dt).tolist() for y, r in zip(twin_tracked, refs)],
        "z_finite": np.isfinite(TZ).all(axis=(1, 2)),
    }
    if a.q:
        cols["z_peak"] = _steps("max", np.abs(TZ))
        cols["integral_cmd"] = _integral_command(traces, TZ, finite=cols["z_finite"], Ki=a.Ki)
    return cols


def _integral_command(traces: list[RunTrace], TZ: np.ndarray, *, finite: np.ndarray, Ki: Any) -> list:
    """Each run's ``|z Ki^T|`` peak per input (None where its integrators are not finite): with one integrator the
    product's every number is one multiplication (``z Ki[j]``, whatever kernel a run alone's product reaches; the
    absolute value drops the sign a BLAS kernel's zero start gives a zero), so it is taken over the block at once;
    with more, run by run (a BLAS kernel's sum order is its own). ``Ki`` is not read when no run's are finite (a
    scheduled law's twin records none)."""
    if not finite.any():
        return [None] * len(traces)
    if Ki.shape[1] == 1:
        peaks = _steps("max", np.abs(TZ[:, :, :1] * Ki[:, 0]))
        return [row if ok else None for row, ok in zip(peaks, finite)]
    return [np.abs(tr.twin_z @ Ki.T).max(axis=0) if ok else None for tr, ok in zip(traces, finite)]


def _tracking(t: np.ndarray, y: np.ndarray, r: np.ndarray) -> dict:
    """:func:`~.metrics.tracking` of each row of ``y``, ``r`` (runs, n): overshoot, settling time, IAE and the
    start, as columns (NaN where a run has none: ``overshoot`` under regulation, ``settle`` when it never settles;
    ``settled_at_once`` where regulation found nothing to measure)."""
    G, n = y.shape
    dt = float(t[1] - t[0]) if n > 1 else 0.0
    e = r - y
    k0 = _starts(r)
    e0 = e[np.arange(G), k0]
    iae = np.sum(np.abs(e), axis=1) * dt
    sign = np.where(e0 != 0, np.sign(e0), 1.0)[:, None]
    scale = np.abs(e0)
    regulation = scale < 1e-12  # no initial error: measured against the largest excursion instead
    if (k0 == k0[0]).all():  # one start for every run (a shared reference): the steps from it, no masks
        seg = e[:, k0[0] :] * sign
        size = np.abs(seg)
        largest, lowest = size.max(axis=1), -seg.min(axis=1)
        scale = np.where(regulation, largest, scale)
        outside = size > (BAND * scale)[:, None]
    else:
        seg = e * sign
        size = np.abs(seg)
        after = np.arange(n)[None, :] >= k0[:, None]
        largest, lowest = np.where(after, size, -np.inf).max(axis=1), -np.where(after, seg, np.inf).min(axis=1)
        scale = np.where(regulation, largest, scale)
        outside = (size > (BAND * scale)[:, None]) & after
    with np.errstate(divide="ignore", invalid="ignore"):
        overshoot = np.where(lowest > 0.0, lowest, 0.0) / scale * 100.0  # Python's max(0.0, x): 0.0 unless x > 0
    last = n - 1 - np.argmax(outside[:, ::-1], axis=1)  # the row's last step outside (its slice ends at n - 1 too)
    settle = t[np.minimum(last + 1, n - 1)] - t[k0]
    settle = np.where(last == n - 1, np.nan, settle)
    settle = np.where(outside.any(axis=1), settle, 0.0)
    return {"overshoot": np.where(regulation, np.nan, overshoot), "settle": settle, "iae": iae, "start": t[k0],
            "at_once": regulation & (scale < 1e-12), "regulation": regulation}  # fmt: skip


def _starts(r: np.ndarray) -> np.ndarray:
    """Each row's start (runs,): the step after its reference's last change, 0 when it never changes; found once
    when the rows are one array every run shares (a view whose runs' stride is 0: the plan's references)."""
    G, n = r.shape
    rows = r[:1] if r.strides[0] == 0 else r
    k0 = np.zeros(rows.shape[0], dtype=np.intp)
    if n > 1:
        change = np.abs(np.diff(rows, axis=1)) > 0
        k0 = np.where(change.any(axis=1), n - 1 - np.argmax(change[:, ::-1], axis=1), 0)
    return np.broadcast_to(k0, (G,)) if rows is not r else k0


def _fin(x: Any) -> float | None:
    """``x`` as a float, None when it is not finite (what ``_clean`` makes of a report's number)."""
    x = float(x)
    return x if math.isfinite(x) else None


def _named(names: list[str], values: list) -> dict:
    """``{name: value}`` of one run's row, non-finite values None."""
    return {name: _fin(v) for name, v in zip(names, values)}


def _metrics_of(j: int, cols: dict, trace: RunTrace, *, artifact: Any, late: int, period_s: float,
                model_start: str, timed: dict) -> dict:  # fmt: skip
    """Run ``j``'s dict of its group's columns, as :func:`~.metrics.compute_metrics` makes it (a new dict, its
    numbers made JSON-able as they are put in, not by walking it afterwards)."""
    a, sig = artifact, artifact.signals
    lost = int(cols["lost"][j])
    out = {
        "steps": int(trace.t.size),
        "lost": lost,
        "late": int(late),
        "deadline_misses": lost,
        "latency_us": dict(timed["latency_us"]),  # cleaned once for the runs that share it
        "period_jitter_us": dict(timed["period_jitter_us"]),
        "period_s": _fin(period_s),
        "saturation_fraction": _named(sig["inputs"], cols["sat_frac"][j]),
        "saturated_steps": int(cols["saturated_steps"][j]),
        "saturated_steps_per_input": dict(zip(sig["inputs"], cols["sat_per_input"][j])),
        "outputs_final": _named(sig["outputs"], cols["y_final"][j]),
        "inputs_peak_abs": _named(sig["inputs"], cols["u_peak"][j]),
        "outputs_peak_abs": _named(sig["outputs"], cols["y_peak"][j]),
        "refused_steps": int(cols["refused"][j]),
    }
    if cols["has_twin"][j]:
        out.update(_twin_of(j, cols["twin"], steps=int(trace.t.size), artifact=a))
    if trace.has_model_twin:
        mismatch = model_mismatch(t=trace.t, y=trace.y, r=trace.r, model_y=trace.model_y, artifact=a,
                                  start=model_start)  # fmt: skip
        out["model_twin"] = _clean(mismatch.to_dict())
    names = sig["references"] if a.q else sig["outputs"]
    out["tracked"] = {name: _tracked_of(j, tr) for name, tr in zip(names, cols["tracked"])}
    return out


def _tracked_of(j: int, tr: dict) -> dict:
    """Run ``j``'s :func:`~.metrics.tracking` dict from the columns of :func:`_tracking`."""
    iae, start = _fin(tr["iae"][j]), _fin(tr["start"][j])
    if tr["at_once"][j]:
        return {"overshoot_pct": None, "settling_time_s": 0.0, "iae": iae, "start_s": start}
    overshoot = None if tr["regulation"][j] else _fin(tr["overshoot"][j])
    return {"overshoot_pct": overshoot, "settling_time_s": _fin(tr["settle"][j]), "iae": iae, "start_s": start}


def _twin_of(j: int, tw: dict, *, steps: int, artifact: Any) -> dict:
    """Run ``j``'s twin figures (``peak_integrator``, ``peak_integral_command``, ``twin``) from the columns of
    :func:`_twin_columns`, as :func:`~.metrics.compute_metrics` and ``TwinComparison.to_dict`` make them."""
    a, sig = artifact, artifact.signals
    out: dict[str, Any] = {}
    if a.q and tw["z_finite"][j]:
        out["peak_integrator"] = _named(sig["references"], tw["z_peak"][j])
        out["peak_integral_command"] = _named(sig["inputs"], tw["integral_cmd"][j].tolist())
    span = (a.u_max - a.u_min).tolist()
    du, dy, excursion = tw["du"][j], tw["dy"][j], tw["excursion"][j]
    du_rel = [d / s if s > 0 else None for d, s in zip(du, span)]
    dy_rel = [d / e if e > 0 else None for d, e in zip(dy, excursion)]
    iae = {}
    for k, name in enumerate(sig["references"] if a.q else sig["outputs"]):
        real, ideal = float(tw["iae_real"][k][j]), float(tw["iae_twin"][k][j])
        iae[name] = {"real": _fin(real), "twin": _fin(ideal), "difference": _fin(real - ideal),
                     "difference_rel": _fin((real - ideal) / ideal) if ideal > 0 else None}  # fmt: skip
    out["twin"] = {
        "steps": steps,
        "inputs": _differences(sig["inputs"], du, du_rel, "max_du"),
        "outputs": _differences(sig["outputs"], dy, dy_rel, "max_dy"),
        "iae": iae,
        "worst_du_rel": _fin(max((r or 0.0 for r in du_rel), default=0.0)),
        "worst_dy_rel": _fin(max((r or 0.0 for r in dy_rel), default=0.0)),
    }
    return out


def _differences(names: list[str], largest: list[float], relative: list, key: str) -> dict:
    """Per signal ``{key: largest, key_rel: relative}`` (non-finite: None)."""
    return {name: {key: _fin(d), f"{key}_rel": None if r is None else _fin(r)}
            for name, d, r in zip(names, largest, relative)}  # fmt: skip
