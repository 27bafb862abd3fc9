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
from dataclasses import dataclass
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
    return metric_trees(traces, artifact=artifact, mode=mode, late=late, period_s=period_s, model_start=model_start,
                        timed=timed).rows()  # fmt: skip


@dataclass(frozen=True)
class BlockMetrics:
    """The metrics of a block's runs as column trees (a dict of trees, or a column: one value a run, as
    :func:`~gainlink.hil.campaign.jsontext.object_texts` takes them): ``trees`` lists (the runs' positions, their
    tree), each run in one; the runs of a dict tree share their metrics' structure (their dicts' keys), and a column
    tree holds each run's dict (a run of no steps: :func:`~.metrics.compute_metrics` itself)."""

    trees: list[tuple[list[int], Any]]
    runs: int

    @property
    def columnar(self) -> bool:
        """Whether every tree is a dict of columns (no run's dict held whole)."""
        return all(isinstance(tree, dict) for _, tree in self.trees)

    def rows(self) -> list[dict]:
        """Each run's dict, as :func:`~.metrics.compute_metrics` makes it (its keys in that order)."""
        out: list[dict | None] = [None] * self.runs
        for positions, tree in self.trees:
            for i, row in zip(positions, tree_rows(tree, len(positions))):
                out[i] = row
        return out  # type: ignore[return-value]

    def completed(self, metrics: list[dict]) -> BlockMetrics:
        """These trees with what each run's final dict (``metrics[i]``: what its result adds to its figures, its
        completion, times, the law's report) holds beyond them as columns; a tree whose runs' dicts differ in those
        keys becomes a column of the dicts. (A result adds keys :func:`~.metrics.compute_metrics` never makes.)"""
        out: list[tuple[list[int], Any]] = []
        for positions, tree in self.trees:
            first = metrics[positions[0]].keys()
            if not isinstance(tree, dict) or not all(metrics[i].keys() == first for i in positions):
                out.append((positions, [metrics[i] for i in positions]))
                continue
            added = [k for k in first if k not in tree]
            out.append((positions, tree | {k: [metrics[i][k] for i in positions] for k in added}))
        return BlockMetrics(out, self.runs)

    def at(self, positions: list[int], runs: int) -> BlockMetrics:
        """The trees of ``runs`` runs of which run ``i`` of these is run ``positions[i]``."""
        return BlockMetrics([([positions[i] for i in rows], tree) for rows, tree in self.trees], runs)


def metric_trees(traces: list[RunTrace], *, artifact: Any, mode: str, late: int, period_s: list[float],
                 model_start: list[str], timed: list[dict]) -> BlockMetrics:  # fmt: skip
    """:func:`block_metrics` as column trees, one per structure of the runs' dicts (their groups of
    :data:`RUNS_AT_ONCE` runs joined)."""
    trees: list[tuple[list[int], Any]] = []
    cleaned: dict[int, dict] = {}
    for t in timed:  # once per dict: the runs of one length share theirs
        if id(t) not in cleaned:
            cleaned[id(t)] = _clean(t)
    lengths: dict[int, list[int]] = {}
    for i, tr in enumerate(traces):
        lengths.setdefault(int(tr.t.size), []).append(i)
    kinds: dict[tuple, list[tuple[list[int], dict]]] = {}
    for n, idx in lengths.items():
        if n == 0:  # nothing to reduce: the run's own function
            trees.append((idx, [compute_metrics(traces[i], artifact=artifact, mode=mode, late=late,
                                                period_s=period_s[i], model_start=model_start[i], timed=timed[i])
                                for i in idx]))  # fmt: skip
            continue
        for part in runs_at_once(idx):
            group = [traces[i] for i in part]
            made = _group_trees(_group(group, artifact=artifact), group, artifact=artifact, late=late,
                                period_s=[period_s[i] for i in part], model_start=[model_start[i] for i in part],
                                timed=[cleaned[id(timed[i])] for i in part])  # fmt: skip
            for kind, rows, tree in made:
                kinds.setdefault(kind, []).append(([part[r] for r in rows], tree))
    for parts in kinds.values():
        trees.append(([i for rows, _ in parts for i in rows], joined([(tree, len(rows)) for rows, tree in parts])))
    return BlockMetrics(trees, len(traces))


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


def _named(names: list[str], A: Any) -> dict[str, list]:
    """``{name: column}`` of ``A`` (runs, len(names)): each name's values, one a run, non-finite ones None."""
    return dict(zip(names, finite_lists(np.asarray(A).T)))


def _group_trees(cols: dict, traces: list[RunTrace], *, artifact: Any, late: int, period_s: list,
                 model_start: list, timed: list) -> list[tuple[tuple, list[int], dict]]:  # fmt: skip
    """The group's metrics as column trees, one per structure its runs' dicts have (with a twin or not, the twin's
    integrator peaks or not, a model twin or not: ``(that key, the runs' positions in the group, the tree)``), each
    tree's keys in :func:`~.metrics.compute_metrics`' order, its numbers made JSON-able (:func:`finite_lists`)."""
    a, sig = artifact, artifact.signals
    G, n = len(traces), int(traces[0].t.size)
    lost = cols["lost"].tolist()
    tree: dict[str, Any] = {
        "steps": [n] * G,
        "lost": lost,
        "late": [int(late)] * G,
        "deadline_misses": lost,
        "latency_us": _shared(timed, "latency_us"),
        "period_jitter_us": _shared(timed, "period_jitter_us"),
        "period_s": [_fin(p) for p in period_s],
        "saturation_fraction": _named(sig["inputs"], cols["sat_frac"]),
        "saturated_steps": cols["saturated_steps"].tolist(),
        "saturated_steps_per_input": dict(zip(sig["inputs"], cols["sat_per_input"].T.tolist())),
        "outputs_final": _named(sig["outputs"], cols["y_final"]),
        "inputs_peak_abs": _named(sig["inputs"], cols["u_peak"]),
        "outputs_peak_abs": _named(sig["outputs"], cols["y_peak"]),
        "refused_steps": cols["refused"].tolist(),
    }
    twin, peak = cols["has_twin"].tolist(), [False] * G
    if "twin" in cols:
        tree |= _twin_tree(cols["twin"], steps=n, artifact=a)
        if "peak_integrator" in tree:  # a run's peaks when it has a twin and its integrators are finite
            peak = (cols["twin"]["z_finite"] & cols["has_twin"]).tolist()
    model = [tr.has_model_twin for tr in traces]
    if any(model):
        tree["model_twin"] = [_model_twin(tr, a, start) if m else None
                              for tr, m, start in zip(traces, model, model_start)]  # fmt: skip
    names = sig["references"] if a.q else sig["outputs"]
    tree["tracked"] = dict(zip(names, map(_tracked_tree, cols["tracked"])))
    kinds: dict[tuple, list[int]] = {}
    for j, kind in enumerate(zip(twin, peak, model)):
        kinds.setdefault(kind, []).append(j)
    return [(kind, rows, _kept_keys(tree, kind, rows, G)) for kind, rows in kinds.items()]


_OF_TWIN = ("peak_integrator", "peak_integral_command", "twin")


def _kept_keys(tree: dict, kind: tuple, rows: list[int], runs: int) -> dict:
    """``tree`` for the runs ``rows`` of one structure ``kind`` (twin, integrator peaks, model twin): the keys they
    lack dropped, their values only (the whole tree when they are all its runs)."""
    twin, peak, model = kind
    lacks = {k for k, has in zip(_OF_TWIN, (peak, peak, twin)) if not has} | (set() if model else {"model_twin"})
    kept = {k: v for k, v in tree.items() if k not in lacks}
    return kept if len(rows) == runs else picked(kept, rows)


def picked(node: Any, rows: list[int]) -> Any:
    """A column tree (a dict of trees, or a column: one value a run) at runs ``rows`` only."""
    if isinstance(node, dict):
        return {key: picked(sub, rows) for key, sub in node.items()}
    return [node[j] for j in rows]


def tree_rows(node: Any, runs: int) -> list:
    """Each run's value of a column tree of ``runs`` runs (a dict of trees: a new dict a run, its keys in the tree's
    order; a column: its values)."""
    if not isinstance(node, dict):
        return node
    if not node:
        return [{} for _ in range(runs)]
    keys = list(node)
    return [dict(zip(keys, values)) for values in zip(*(tree_rows(sub, runs) for sub in node.values()))]


def joined(parts: list[tuple[Any, int]]) -> Any:
    """Column trees of runs of one structure (``(tree, its runs)`` each) as one: each column the runs' of each tree in
    turn; a level where the trees differ (a dict's keys, a column against a dict) a column of the runs' values."""
    first = parts[0][0]
    if len(parts) == 1:
        return first
    if isinstance(first, dict) and all(isinstance(t, dict) and list(t) == list(first) for t, _ in parts):
        return {key: joined([(t[key], runs) for t, runs in parts]) for key in first}
    return [v for t, runs in parts for v in tree_rows(t, runs)]


def _shared(timed: list[dict], key: str) -> Any:
    """The column tree of the runs' ``timed[j][key]`` dicts (cleaned once for the runs that share one): a column of
    each run's copy when they differ."""
    first = timed[0][key]
    if all(t is timed[0] for t in timed):
        return {k: [v] * len(timed) for k, v in first.items()}
    return [dict(t[key]) for t in timed]


def _model_twin(trace: RunTrace, artifact: Any, start: str) -> dict:
    """The run's model twin's figures (:func:`~.model_twin.model_mismatch`), JSON-able."""
    mismatch = model_mismatch(t=trace.t, y=trace.y, r=trace.r, model_y=trace.model_y, artifact=artifact, start=start)
    return _clean(mismatch.to_dict())


def _tracked_tree(tr: dict) -> dict:
    """A tracked signal's :func:`~.metrics.tracking` figures as columns, from those of :func:`_tracking` (a run that
    settled at once: no overshoot and a settling time of 0)."""
    at_once, regulation = tr["at_once"].tolist(), tr["regulation"].tolist()
    overshoot, settle = finite_lists(tr["overshoot"]), finite_lists(tr["settle"])
    return {
        "overshoot_pct": [None if at_once[j] or regulation[j] else v for j, v in enumerate(overshoot)],
        "settling_time_s": [0.0 if at_once[j] else v for j, v in enumerate(settle)],
        "iae": finite_lists(tr["iae"]),
        "start_s": finite_lists(tr["start"]),
    }


def _twin_tree(tw: dict, *, steps: int, artifact: Any) -> dict:
    """The twin's figures (``peak_integrator``, ``peak_integral_command``, ``twin``) as columns, from those of
    :func:`_twin_columns`, as :func:`~.metrics.compute_metrics` and ``TwinComparison.to_dict`` make them: the
    relative figures the same IEEE operations, taken over the group (a run's are read only when it has a twin; the
    peaks only when its integrators are finite)."""
    a, sig = artifact, artifact.signals
    runs = tw["du"].shape[0]
    span = a.u_max - a.u_min
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # NaN where a run alone has None
        du_rel = np.where(span > 0, tw["du"] / span, np.nan)
        dy_rel = np.where(tw["excursion"] > 0, tw["dy"] / tw["excursion"], np.nan)
    iae = {}
    for k, name in enumerate(sig["references"] if a.q else sig["outputs"]):
        real, ideal = tw["iae_real"][k], tw["iae_twin"][k]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rel = np.where(ideal > 0, (real - ideal) / ideal, np.nan)
        iae[name] = dict(zip(("real", "twin", "difference", "difference_rel"),
                             map(finite_lists, (real, ideal, real - ideal, rel))))  # fmt: skip
    out: dict[str, Any] = {}
    if a.q and tw["z_finite"].any():
        out["peak_integrator"] = _named(sig["references"], tw["z_peak"])
        out["peak_integral_command"] = _named(sig["inputs"], tw["integral_cmd"])
    out["twin"] = {
        "steps": [steps] * runs,
        "inputs": _differences(sig["inputs"], tw["du"], du_rel, "max_du"),
        "outputs": _differences(sig["outputs"], tw["dy"], dy_rel, "max_dy"),
        "iae": iae,
        "worst_du_rel": _worst(np.where(span > 0, du_rel, 0.0)),
        "worst_dy_rel": _worst(np.where(tw["excursion"] > 0, dy_rel, 0.0)),
    }
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


def _differences(names: list[str], largest: np.ndarray, relative: np.ndarray, key: str) -> dict:
    """``{name: {key: column, key_rel: column}}`` of each run's largest and relative differences (non-finite: None)."""
    big, rel = finite_lists(largest.T), finite_lists(relative.T)
    return {name: {key: b, f"{key}_rel": r} for name, b, r in zip(names, big, rel)}
