"""A campaign's rows (one per planned run, with its verdict), streamed from the store in plan order, and the tally
the report is drawn from, kept in numpy arrays indexed by the plan.

Each block file is read once: each kept run's stored row (metrics, measures, worker: not its inputs) is decoded once
and judged (:func:`verdict_head`), its verdict's JSON text (the head's and the stored row's text joined) and its
``campaign.csv`` cells go, as one line, to an anonymous temporary file, and its numbers (status, IAE, model mismatch,
failed criteria) to arrays indexed by the plan's distinct runs. The planned runs are then walked in plan order: each
row's JSON is its head's (the plan's) and its verdict's texts joined, its CSV row its head's cells and its stored
cells, with nothing decoded again but the reasons of failed runs. Nothing holds every row: the client keeps an offset
and a few numbers a run (:class:`Tally`: each run's status, IAE and scatter coordinates, 8 bytes each).
"""

from __future__ import annotations

import heapq
import json
import math
import tempfile
from array import array
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from .criteria import evaluate

FAILURES_LIMIT = 200
WORST = 3
STATUSES = ("pass", "fail", "error", "missing")  # a run's status code is its place here
PASS, FAIL, ERROR, MISSING = range(4)
SEP = "\x00"  # between a spilled line's fields (JSON and CSV cells hold no NUL: json escapes it, reasons are text)


def verdict_head(status: str, row: dict, reason: str | None, criteria: Any) -> dict:
    """What a run's row says beyond its stored ``row`` (:data:`~.store.ROW_KEYS` and ``run_reason``: complete,
    metrics, measures, worker, the run's own reason): its status (``pass``, ``fail``, ``error``), the criteria it
    failed and the reasons; and ``None`` for any of ``complete``, ``run_reason``, ``worker`` the row lacks."""
    if status == "error":
        return {"status": "error", "failed": ["error"], "reasons": [reason]} | (
            {} if "worker" in row else {"worker": None}
        )
    failed = evaluate(criteria, row)
    missing = {k: None for k in ("complete", "run_reason", "worker") if k not in row}
    return {"status": "fail" if failed else "pass", "failed": sorted({k for k, _ in failed}),
            "reasons": [text for _, text in failed]} | missing  # fmt: skip


def point_row(point: Any) -> dict:
    """The part of a run's row its planned point gives."""
    return {
        "index": point.index,
        "id": point.id,
        "grid_index": point.grid_index,
        "draw": point.draw,
        "values": point.values,
        "seed": point.seed,
        "artifact_sha256": point.artifact_sha256,
    }


MISSING_VERDICT = {"status": "missing", "failed": ["missing"], "reasons": ["no result"]}
METRIC_CELLS = ("iae", "overshoot_pct", "settling_time_s")
MEASURE_CELLS = (
    "stable",
    "longest_saturation_s",
    "twin_output_deviation",
    "twin_command_deviation",
    "model_mismatch",
    "model_iae_ratio",
)


def csv_cells(v: dict) -> tuple[list[str], tuple[str, ...], tuple[str, ...]]:
    """A verdict's ``campaign.csv`` cells after the axes and seed: the reasons and measures, then each tracked output's
    metrics and each output's final value in the run's own sorted order (returned with those names)."""
    m, q = v.get("metrics", {}), v.get("measures", {})
    tracked, outs = tuple(sorted(m.get("tracked", {}))), tuple(sorted(m.get("outputs_final", {})))
    values = [
        v.get("complete"),
        *(q.get(k) for k in MEASURE_CELLS),
        *(m["tracked"][t].get(k) for t in tracked for k in METRIC_CELLS),
        *(m["outputs_final"][o] for o in outs),
    ]
    cells = ["; ".join(v["reasons"])]  # then each as csv.writer writes it (floats by repr, None empty), inline
    cells += [repr(x) if isinstance(x, float) else "" if x is None else str(x) for x in values]
    return cells, tracked, outs


FIXED_CELLS = 8


def tracked_iae(row: dict) -> float | None:
    """The run's IAE summed over its tracked outputs (``None`` without one, or when one has none)."""
    tr = row.get("metrics", {}).get("tracked", {})
    vals = [v.get("iae") for v in tr.values()]
    return None if not vals or any(v is None for v in vals) else float(sum(vals))


class Verdicts:
    """Every stored run's verdict, made once from its record and spilled to an anonymous temporary file (gone when
    closed) with its ``campaign.csv`` cells; its numbers in arrays indexed by the plan's distinct runs (``ids``, ASCII
    bytes in plan order; a run planned twice is one run). The tracked outputs and outputs the runs report are the
    CSV's columns."""

    def __init__(self, store: Any, criteria: Any, ids: np.ndarray) -> None:
        self.file: IO[bytes] = tempfile.TemporaryFile()
        self.uids, self.slot = np.unique(ids, return_inverse=True)
        n = len(self.uids)
        self.at, self.size = np.full(n, -1, np.int64), np.zeros(n, np.int32)
        self.code = np.full(n, MISSING, np.int8)
        self.iae, self.model = np.full(n, np.nan), np.full(n, np.nan)
        self.warning = np.zeros(n, bool)
        self.failed = np.zeros(n, np.int64)  # bit k: failed criterion self.criteria[k]
        self.criteria: list[str] = []
        self.shape = np.zeros(n, np.int16)  # the run's (tracked, outputs) names: self.shapes[shape]
        self.shapes: list[tuple[tuple[str, ...], tuple[str, ...]]] = []
        self.tracked: set[str] = set()
        self.outputs: set[str] = set()
        self._heads: dict[tuple, str] = {}
        for run_ids, statuses, rows, reasons in store.report_parts():
            k = np.minimum(np.searchsorted(self.uids, run_ids), max(n - 1, 0))
            planned = (self.uids[k] == run_ids).tolist() if n else [False] * len(run_ids)
            for i, u in enumerate(k.tolist()):
                if planned[i]:
                    self._add(u, statuses[i], rows[i], reasons[i], criteria)

    def _add(self, u: int, status: str, row_text: str, reason: str | None, criteria: Any) -> None:
        """Spill run ``u``'s verdict (from its status, its stored row's JSON text and an error's reason) and note its
        numbers. The verdict's text is its head's and the stored row's joined: the row is decoded, not encoded
        again."""
        row = json.loads(row_text)
        head = verdict_head(status, row, reason, criteria)
        v = head | row
        cells, tracked, outs = csv_cells(v)
        shape = (tracked, outs)
        if shape not in self.shapes:
            self.shapes.append(shape)
            self.tracked.update(tracked)
            self.outputs.update(outs)
        self.shape[u] = self.shapes.index(shape)
        text = self._head_text(head)
        body = text if row_text == "{}" else text[:-1] + ", " + row_text[1:]
        data = SEP.join([body, *cells]).encode("utf-8")
        self.at[u], self.size[u] = self.file.tell(), len(data)
        self.file.write(data)
        self.code[u] = STATUSES.index(v["status"])
        iae = tracked_iae(v)
        self.iae[u] = math.nan if iae is None else iae
        q = v.get("measures", {})
        if q.get("model_mismatch") is not None:
            self.model[u] = q["model_mismatch"]
        self.warning[u] = bool(q.get("model_warning"))
        for name in v["failed"]:
            if name not in self.criteria:
                self.criteria.append(name)
            self.failed[u] |= 1 << self.criteria.index(name)

    def _head_text(self, head: dict) -> str:
        """``head`` as JSON text; a head without a reason (a passed run's, the same for most runs) encoded once."""
        if head["reasons"] or head["failed"]:
            return json.dumps(head, sort_keys=True, allow_nan=False)
        key = tuple((k, v) for k, v in head.items() if k not in ("failed", "reasons"))  # its status and Nones
        if key not in self._heads:
            self._heads[key] = json.dumps(head, sort_keys=True, allow_nan=False)
        return self._heads[key]

    def text(self, u: int) -> tuple[str, list[str]]:
        """Run ``u``'s verdict as JSON text and its CSV cells (:data:`MISSING_VERDICT` without a record)."""
        if self.at[u] < 0:
            return json.dumps(MISSING_VERDICT, sort_keys=True), ["no result"] + [""] * (FIXED_CELLS - 1)
        self.file.seek(self.at[u])
        body, *cells = self.file.read(self.size[u]).decode("utf-8").split(SEP)
        return body, cells

    def cells(self, u: int, cells: list[str], tracked: list[str], outs: list[str]) -> list[str]:
        """Run ``u``'s CSV cells in the columns ``tracked`` and ``outs`` (sorted) of every run."""
        own_tracked, own_outs = self.shapes[self.shape[u]] if self.at[u] >= 0 else ((), ())
        if list(own_tracked) == tracked and list(own_outs) == outs:
            return cells
        fixed, rest = cells[:FIXED_CELLS], cells[FIXED_CELLS:]
        by_t = {t: rest[3 * i : 3 * i + 3] for i, t in enumerate(own_tracked)}
        by_o = {o: rest[3 * len(own_tracked) + i] for i, o in enumerate(own_outs)}
        return [*fixed, *(c for t in tracked for c in by_t.get(t, ["", "", ""])), *(by_o.get(o, "") for o in outs)]

    def close(self) -> None:
        self.file.close()


class _Top:
    """The ``limit`` smallest items by key (ties: the earliest added), a bounded heap."""

    def __init__(self, limit: int) -> None:
        self.limit, self.heap, self.seen = limit, [], 0

    def add(self, key: tuple, item: Any) -> None:
        entry = tuple(-k for k in key) + (-self.seen, item)  # max-heap of the kept ones: drop the largest key
        self.seen += 1
        if len(self.heap) < self.limit:
            heapq.heappush(self.heap, entry)
        elif entry > self.heap[0]:
            heapq.heapreplace(self.heap, entry)

    def items(self) -> list:
        return [e[-1] for e in sorted(self.heap, reverse=True)]


class Tally:
    """What the report says of the rows: each planned run's status, IAE and grid point in arrays (from
    :class:`Verdicts`' arrays, indexed by plan order), and what :meth:`add` gathers in the walk (the grid points'
    values, the :data:`FAILURES_LIMIT` worst failed runs, the scatter plot's coordinates: an axis is plotted when every
    run's value is a number). :meth:`finish` makes the counts by status and by failed criterion, each grid point's
    counts and IAE median and 95th percentile (numpy's exact ones), the worst runs, the largest model mismatch and the
    finished runs' pass/fail (the envelopes' runs)."""

    def __init__(self, plan: Any, verdicts: Verdicts) -> None:
        self.verdicts = verdicts
        self.grid_names = [a.name for a in plan.campaign.grid]
        self.axes = [a.name for a in (*plan.campaign.draws, *plan.campaign.grid)]
        self.numeric = dict.fromkeys(self.axes, True)
        self.failures = _Top(FAILURES_LIMIT)
        self.bad = 0
        self._grid = array("i")
        self._grid_values: dict[int, dict] = {}
        self.scatter = {name: array("d") for name in self.axes}
        self.scatter_iae, self.scatter_fail = array("d"), array("b")

    def add(self, head: Any, u: int) -> None:
        """Count planned run ``head`` (its verdict: the verdicts' run ``u``)."""
        code, iae = int(self.verdicts.code[u]), float(self.verdicts.iae[u])
        g = head.grid_index
        self._grid.append(g)
        if g not in self._grid_values:
            self._grid_values[g] = {k: head.values[k] for k in self.grid_names}
        if code != PASS:
            self.bad += 1
            key = (code != FAIL, -(iae if iae and not math.isnan(iae) else math.inf) if code == FAIL else 0)
            self.failures.add(key, (head.index, head.id, STATUSES[code], head.values, u))
        if not math.isnan(iae):
            for name in self.axes:
                v = head.values[name]
                ok = isinstance(v, (int, float)) and not isinstance(v, bool)
                self.numeric[name] = self.numeric[name] and ok
                self.scatter[name].append(float(v) if ok else math.nan)
            self.scatter_iae.append(iae)
            self.scatter_fail.append(code == FAIL)

    def finish(self, ids: np.ndarray) -> None:
        """The tallies of the walked runs (``ids``: theirs, in plan order, ASCII bytes)."""
        v, slot = self.verdicts, self.verdicts.slot[: len(self._grid)]
        code, iae = v.code[slot], v.iae[slot]
        self.counts = Counter({STATUSES[c]: int(n) for c, n in enumerate(np.bincount(code, minlength=4)) if n})
        self.failed = self._failed_counts(v.failed[slot])
        finite = np.flatnonzero(~np.isnan(iae))
        worst = finite[np.lexsort((finite, -iae[finite]))][:WORST]
        self.worst_runs = [(int(k), ids[k].decode("ascii"), float(iae[k]), STATUSES[code[k]]) for k in worst]
        model = v.model[slot]
        k = int(np.nanargmax(model)) if not np.isnan(model).all() else -1
        self.model = None if k < 0 else (float(model[k]), k, ids[k].decode("ascii"))
        self.flagged = int(v.warning[slot].sum())
        finished = code <= FAIL
        self.status = RunStatus(ids[finished], code[finished] == FAIL)
        self._points(np.frombuffer(self._grid, np.int32), code, iae)
        self._failure_rows = self._failures()

    def _failed_counts(self, masks: np.ndarray) -> Counter:
        """Runs failing each criterion, most first (ties: the criterion met first in plan order, as a Counter fed
        row by row gives them)."""
        found = []
        for bit, name in enumerate(self.verdicts.criteria):
            hit = (masks >> bit) & 1 == 1
            if hit.any():
                found.append((-int(hit.sum()), int(hit.argmax()), name))
        return Counter({name: -n for n, _, name in sorted(found)})

    def _points(self, grid: np.ndarray, code: np.ndarray, iae: np.ndarray) -> None:
        self.point_rows = []
        for g, values in self._grid_values.items():
            mine = grid == g
            c = np.bincount(code[mine], minlength=4)
            runs = int(mine.sum())
            vals = iae[mine & ~np.isnan(iae)]
            self.point_rows.append(
                {"grid_index": g, "values": values, "runs": runs, "pass": int(c[PASS]), "fail": int(c[FAIL]),
                 "error": int(c[ERROR] + c[MISSING]), "pass_fraction": int(c[PASS]) / runs,
                 "iae_median": float(np.median(vals)) if vals.size else None,
                 "iae_p95": float(np.percentile(vals, 95)) if vals.size else None}
            )  # fmt: skip

    @property
    def runs(self) -> int:
        return len(self._grid)

    def point_list(self) -> list[dict]:
        """The grid points (in the order first met), with pass fraction and IAE median and 95th percentile."""
        return self.point_rows

    def failure_rows(self) -> list[dict]:
        """The :data:`FAILURES_LIMIT` worst failed runs (index, id, status, values, reasons), worst first; errors
        last."""
        return self._failure_rows

    def _failures(self) -> list[dict]:
        out = []
        for index, run_id, status, values, u in self.failures.items():  # their reasons: the only verdicts read again
            reasons = json.loads(self.verdicts.text(u)[0])["reasons"]
            out.append({"index": index, "id": run_id, "status": status, "values": values, "reasons": reasons})
        return out


class RunStatus(Mapping):
    """Run id -> ``pass`` or ``fail``, held as two arrays: the ids (ASCII bytes) and whether each failed."""

    def __init__(self, ids: np.ndarray, failed: np.ndarray) -> None:
        self.ids, self.failed = ids, failed

    def __len__(self) -> int:
        return len(self.ids)

    def __iter__(self) -> Iterator[str]:
        return (i.decode("ascii") for i in self.ids.tolist())

    def __getitem__(self, run_id: str) -> str:
        hit = np.flatnonzero(self.ids == run_id.encode("ascii", "replace"))
        if not hit.size:
            raise KeyError(run_id)
        return "fail" if self.failed[hit[0]] else "pass"


class ReportRows(Sequence):
    """The runs of a merged report (``campaign.json``'s ``runs``), read from the file when asked, one line each:
    iterating streams them, ``rows[i]`` reads up to the ``i``-th. The file is the newest merge's."""

    def __init__(self, path: Path, count: int) -> None:
        self.path, self.count = Path(path), count

    def __len__(self) -> int:
        return self.count

    def __iter__(self) -> Iterator[dict]:
        with self.path.open("r", encoding="utf-8") as fh:
            for line in fh:
                if line == ' "runs": [\n':
                    break
            for line in fh:
                if not line.startswith("  {"):
                    return
                yield json.loads(line.strip().rstrip(","))

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return list(self)[i]
        k = i + self.count if i < 0 else i
        if not 0 <= k < self.count:
            raise IndexError(i)
        for j, row in enumerate(self):
            if j == k:
                return row
        raise IndexError(i)
