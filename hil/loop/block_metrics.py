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
        for part in runs_at_once(idx):
            group = [traces[i] for i in part]
            made = _group_metrics(_group(group, artifact=artifact), group, artifact=artifact, late=late,
                                  period_s=[period_s[i] for i in part], model_start=[model_start[i] for i in part],
                                  timed=[cleaned[id(timed[i])] for i in part])  # fmt: skip
            for i, metrics in zip(part, made):
                out[i] = metrics
    return out  # type: ignore[return-value]


#: Runs whose columns are reduced together: a figure's (runs, steps) arrays of runs of 1,000 steps ~1 MB, in cache
#: for the next pass over them (block_metrics over 1,667 pendulum runs: 0.11 us a run-step at once, 0.064 by 128,
#: 0.069 by 64, 0.10 by 32). Each run's numbers are the same whatever the count: every figure is taken along a
#: run's own steps.
RUNS_AT_ONCE = 128


def runs_at_once(idx: list[int]) -> list[list[int]]:
    """``idx`` in consecutive parts of at most :data:`RUNS_AT_ONCE`."""
    return [idx[k : k + RUNS_AT_ONCE] for k in range(0, len(idx), RUNS_AT_ONCE)]


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
    cols["tracked"] = [_tracking(t, yj, rj) for yj, rj in zip(tracked_y, refs)]
    TU = stacked([tr.twin_u for tr in traces])
    twin = np.isfinite(TU).all(axis=(1, 2))  # RunTrace.has_twin of each (n > 0 here)
    cols["has_twin"] = twin
    if twin.any():
        cols["twin"] = _twin_columns(traces, Y=Y, U=U, TU=TU, tracked_y=tracked_y, refs=refs, t=t, artifact=a)
    return cols


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
        "iae_real": [np.sum(np.abs(r - y), axis=1) * dt for y, r in zip(tracked_y, refs)],
        "iae_twin": [np.sum(np.abs(r - y), axis=1) * dt for y, r in zip(twin_tracked, refs)],
        "z_finite": np.isfinite(TZ).all(axis=(1, 2)),
    }
    if a.q:
        cols["z_peak"] = _steps("max", np.abs(TZ))
        cols["integral_cmd"] = _integral_command(traces, TZ, finite=cols["z_finite"], Ki=a.Ki)
    return cols


def _integral_command(traces: list[RunTrace], TZ: np.ndarray, *, finite: np.ndarray, Ki: Any) -> np.ndarray:
    """Each run's ``|z Ki^T|`` peak per input (runs, inputs) (a row of NaN where its integrators are not finite: never
    read): with one integrator the product's every number is one multiplication (``z Ki[j]``, whatever kernel a run
    alone's product reaches; the absolute value drops the sign a BLAS kernel's zero start gives a zero), so it is
    taken over the block at once; with more, run by run (a BLAS kernel's sum order is its own). ``Ki`` is not read
    when no run's are finite (a scheduled law's twin records none)."""
    if not finite.any():
        return np.full((len(traces), 0), np.nan)
    if Ki.shape[1] == 1:
        return _steps("max", np.abs(TZ[:, :, :1] * Ki[:, 0]))
    nan = np.full(Ki.shape[0], np.nan)
    return np.stack([np.abs(tr.twin_z @ Ki.T).max(axis=0) if ok else nan for tr, ok in zip(traces, finite)])


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


def finite_lists(A: Any) -> list:
    """Every number of ``A`` (runs, ...) as nested lists of Python floats, the non-finite ones None (what ``_fin``
    makes of each), converted at once: one ``tolist`` and the few non-finite numbers made None where they are."""
    A = np.asarray(A, dtype=float)
    out = A.tolist()
    for at in np.argwhere(~np.isfinite(A)).tolist():
        row = out
        for k in at[:-1]:
            row = row[k]
        row[at[-1]] = None
    return out


def _named_rows(names: list[str], A: Any) -> list[dict]:
    """Each run's ``{name: value}`` of its row of ``A`` (runs, len(names)), non-finite values None."""
    return [dict(zip(names, row)) for row in finite_lists(A)]


def _group_metrics(cols: dict, traces: list[RunTrace], *, artifact: Any, late: int, period_s: list,
                   model_start: list, timed: list) -> list[dict]:  # fmt: skip
    """Each run's dict of its group's columns, as :func:`~.metrics.compute_metrics` makes it (a new dict per run,
    its keys in that order, its numbers made JSON-able as they are put in): each figure converted for the group at
    once (:func:`finite_lists`), then each run's dict put together from the lists."""
    a, sig = artifact, artifact.signals
    n = int(traces[0].t.size)
    lost, refused = cols["lost"].tolist(), cols["refused"].tolist()
    sat_frac, final = _named_rows(sig["inputs"], cols["sat_frac"]), _named_rows(sig["outputs"], cols["y_final"])
    u_peak, y_peak = _named_rows(sig["inputs"], cols["u_peak"]), _named_rows(sig["outputs"], cols["y_peak"])
    sat_steps, per_input = cols["saturated_steps"].tolist(), cols["sat_per_input"].tolist()
    has_twin = cols["has_twin"].tolist()
    twins = _twin_dicts(cols["twin"], steps=n, artifact=a) if "twin" in cols else None
    names = sig["references"] if a.q else sig["outputs"]
    tracked = [_tracked_dicts(tr) for tr in cols["tracked"]]
    out = []
    for j, (trace, tm) in enumerate(zip(traces, timed)):
        run = {
            "steps": n,
            "lost": lost[j],
            "late": int(late),
            "deadline_misses": lost[j],
            "latency_us": dict(tm["latency_us"]),  # cleaned once for the runs that share it
            "period_jitter_us": dict(tm["period_jitter_us"]),
            "period_s": _fin(period_s[j]),
            "saturation_fraction": sat_frac[j],
            "saturated_steps": sat_steps[j],
            "saturated_steps_per_input": dict(zip(sig["inputs"], per_input[j])),
            "outputs_final": final[j],
            "inputs_peak_abs": u_peak[j],
            "outputs_peak_abs": y_peak[j],
            "refused_steps": refused[j],
        }
        if has_twin[j]:
            run.update(twins[j])  # type: ignore[index]
        if trace.has_model_twin:
            mismatch = model_mismatch(t=trace.t, y=trace.y, r=trace.r, model_y=trace.model_y, artifact=a,
                                      start=model_start[j])  # fmt: skip
            run["model_twin"] = _clean(mismatch.to_dict())
        run["tracked"] = {name: tr[j] for name, tr in zip(names, tracked)}
        out.append(run)
    return out


def _tracked_dicts(tr: dict) -> list[dict]:
    """Each run's :func:`~.metrics.tracking` dict from the columns of :func:`_tracking`."""
    iae, start, settle, overshoot = (
        finite_lists(tr["iae"]),
        finite_lists(tr["start"]),
        finite_lists(tr["settle"]),
        finite_lists(tr["overshoot"]),
    )
    at_once, regulation = tr["at_once"].tolist(), tr["regulation"].tolist()
    return [{"overshoot_pct": None, "settling_time_s": 0.0, "iae": iae[j], "start_s": start[j]} if at_once[j] else
            {"overshoot_pct": None if regulation[j] else overshoot[j], "settling_time_s": settle[j], "iae": iae[j],
             "start_s": start[j]}
            for j in range(len(iae))]  # fmt: skip


def _twin_dicts(tw: dict, *, steps: int, artifact: Any) -> list[dict]:
    """Each run's twin figures (``peak_integrator``, ``peak_integral_command``, ``twin``) from the columns of
    :func:`_twin_columns`, as :func:`~.metrics.compute_metrics` and ``TwinComparison.to_dict`` make them: the
    relative figures the same IEEE operations, taken over the group (a run's are read only when it has a twin)."""
    a, sig = artifact, artifact.signals
    span = a.u_max - a.u_min
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # NaN where a run alone has None
        du_rel = np.where(span > 0, tw["du"] / span, np.nan)
        dy_rel = np.where(tw["excursion"] > 0, tw["dy"] / tw["excursion"], np.nan)
    inputs = _differences(sig["inputs"], tw["du"], du_rel, "max_du")
    outputs = _differences(sig["outputs"], tw["dy"], dy_rel, "max_dy")
    worst_du = _worst(np.where(span > 0, du_rel, 0.0))
    worst_dy = _worst(np.where(tw["excursion"] > 0, dy_rel, 0.0))
    iae: list[dict] = [{} for _ in range(tw["du"].shape[0])]
    for k, name in enumerate(sig["references"] if a.q else sig["outputs"]):
        real, ideal = tw["iae_real"][k], tw["iae_twin"][k]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rel = np.where(ideal > 0, (real - ideal) / ideal, np.nan)
        for row, values in zip(
            iae, zip(finite_lists(real), finite_lists(ideal), finite_lists(real - ideal), finite_lists(rel))
        ):
            row[name] = dict(zip(("real", "twin", "difference", "difference_rel"), values))
    peaks = bool(a.q) and bool(tw["z_finite"].any())
    z_peak = _named_rows(sig["references"], tw["z_peak"]) if peaks else []
    command = _named_rows(sig["inputs"], tw["integral_cmd"]) if peaks else []
    finite = tw["z_finite"].tolist()
    out = []
    for j in range(len(iae)):
        run: dict[str, Any] = {}
        if peaks and finite[j]:
            run["peak_integrator"], run["peak_integral_command"] = z_peak[j], command[j]
        run["twin"] = {"steps": steps, "inputs": inputs[j], "outputs": outputs[j], "iae": iae[j],
                       "worst_du_rel": worst_du[j], "worst_dy_rel": worst_dy[j]}  # fmt: skip
        out.append(run)
    return out


def _worst(values: np.ndarray) -> list:
    """Each run's ``_fin(max(row, default=0.0))`` of ``values`` (runs, width): a run's relative figures, 0.0 where
    a run alone has None (``r or 0.0``). A row without NaN is reduced by numpy (its numbers are >= 0 or infinite:
    the same maximum); a row with one by Python's ``max``, which keeps a NaN it starts with and passes over later
    ones."""
    if not values.shape[1]:
        return [0.0] * values.shape[0]
    worst = finite_lists(values.max(axis=1))
    for j in np.flatnonzero(np.isnan(values).any(axis=1)).tolist():
        worst[j] = _fin(max(values[j].tolist()))
    return worst


def _differences(names: list[str], largest: np.ndarray, relative: np.ndarray, key: str) -> list[dict]:
    """Each run's ``{name: {key: largest, key_rel: relative}}`` (non-finite: None)."""
    rel_key = f"{key}_rel"
    return [{name: {key: d, rel_key: r} for name, d, r in zip(names, big, rel)}
            for big, rel in zip(finite_lists(largest), finite_lists(relative))]  # fmt: skip
