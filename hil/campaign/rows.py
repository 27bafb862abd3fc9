"""A campaign's rows (one per planned run, with its verdict), streamed from the store in plan order, and the tally
the report is drawn from, kept in bounded memory.

The block files are read one at a time: each stored run's verdict (:func:`verdict`) goes, as a JSON line, to an
anonymous temporary file, with its offset kept by run id; the planned runs are then walked in plan order and each
row is made from its point and its verdict read back at that offset. Nothing holds every row: the client keeps one
offset per stored run and the :class:`Tally` (counters, the worst runs, and per run a few floats: each grid point's
IAE values for its exact quantiles and the scatter plot's coordinates, 8 bytes each).
"""

from __future__ import annotations

import heapq
import json
import math
import tempfile
from array import array
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from .criteria import evaluate

FAILURES_LIMIT = 200
WORST = 3


def verdict(record: dict, criteria: Any) -> dict:
    """The part of a run's row its stored ``record`` gives: status (``pass``, ``fail``, ``error``), the criteria it
    failed, the reasons, metrics and measures."""
    if record["status"] == "error":
        return {"status": "error", "failed": ["error"], "reasons": [record["reason"]], "worker": record.get("worker")}
    failed = evaluate(criteria, record)
    return {
        "status": "fail" if failed else "pass",
        "failed": sorted({k for k, _ in failed}),
        "reasons": [text for _, text in failed],
        "complete": record["complete"],
        "run_reason": record.get("reason"),
        "metrics": record["metrics"],
        "measures": record["measures"],
        "worker": record.get("worker"),
    }


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


MISSING = {"status": "missing", "failed": ["missing"], "reasons": ["no result"]}


class Verdicts:
    """Every stored run's verdict, spilled to an anonymous temporary file (gone when closed), by run id; and the
    tracked outputs and final outputs the runs report (the CSV's columns)."""

    def __init__(self, store: Any, criteria: Any) -> None:
        self.file: IO[bytes] = tempfile.TemporaryFile()
        self.at: dict[str, tuple[int, int]] = {}
        self.tracked: set[str] = set()
        self.outputs: set[str] = set()
        for run_id, record in store.records():
            v = verdict(record, criteria)
            self.tracked.update(v.get("metrics", {}).get("tracked", {}))
            self.outputs.update(v.get("metrics", {}).get("outputs_final", {}))
            data = json.dumps(v, sort_keys=True, allow_nan=False).encode("utf-8")
            self.at[run_id] = (self.file.tell(), len(data))
            self.file.write(data)

    def get(self, run_id: str) -> dict:
        """The verdict of ``run_id`` (:data:`MISSING` without a record)."""
        hit = self.at.get(run_id)
        if hit is None:
            return MISSING
        self.file.seek(hit[0])
        return json.loads(self.file.read(hit[1]))

    def rows(self, points: Iterable[Any]) -> Iterator[dict]:
        """One row per planned point, in plan order."""
        for point in points:
            yield point_row(point) | self.get(point.id)

    def close(self) -> None:
        self.file.close()


def tracked_iae(row: dict) -> float | None:
    """The run's IAE summed over its tracked outputs (``None`` without one, or when one has none)."""
    tr = row.get("metrics", {}).get("tracked", {})
    vals = [v.get("iae") for v in tr.values()]
    return None if not vals or any(v is None for v in vals) else float(sum(vals))


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
    """What the report says of the rows, gathered one row at a time (:meth:`add`).

    Counts by status and by failed criterion, each grid point's counts and IAE values (its median and 95th
    percentile are numpy's exact ones), the worst runs, the :data:`FAILURES_LIMIT` worst failed runs, the largest
    model mismatch, the pass/fail status of each finished run (the envelopes' runs) and the scatter plot's
    coordinates (an axis is plotted when every run's value is a number).
    """

    def __init__(self, plan: Any) -> None:
        self.grid_names = [a.name for a in plan.campaign.grid]
        self.axes = [a.name for a in (*plan.campaign.draws, *plan.campaign.grid)]
        self.numeric = dict.fromkeys(self.axes, True)
        self.counts: Counter = Counter()
        self.failed: Counter = Counter()
        self.points: dict[int, dict] = {}
        self.iae: dict[int, array] = {}
        self.worst, self.failures = _Top(WORST), _Top(FAILURES_LIMIT)
        self.bad = 0
        self.model: tuple[float, int, str] | None = None
        self.flagged = 0
        self.status: dict[str, str] = {}
        self.scatter = {name: array("d") for name in self.axes}
        self.scatter_iae, self.scatter_fail = array("d"), array("b")

    @property
    def runs(self) -> int:
        return sum(self.counts.values())

    def add(self, row: dict) -> None:
        """Count one row."""
        status = row["status"]
        self.counts[status] += 1
        self.failed.update(row["failed"])
        self._point(row, status)
        iae = tracked_iae(row)
        if status in ("pass", "fail"):
            self.status[row["id"]] = status
        if status != "pass":
            self.bad += 1
            key = (status != "fail", -(iae or math.inf) if status == "fail" else 0)
            self.failures.add(key, _failure(row))
        if iae is not None:
            self.worst.add((-iae,), (row["index"], row["id"], iae, status))
            self._scatter(row, iae, status)
        self._model(row)

    def _point(self, row: dict, status: str) -> None:
        g = row["grid_index"]
        p = self.points.setdefault(
            g,
            {"grid_index": g, "values": {k: row["values"][k] for k in self.grid_names}, "runs": 0}
            | dict.fromkeys(("pass", "fail", "error"), 0),
        )
        p["runs"] += 1
        p[status if status in ("pass", "fail", "error") else "error"] += 1
        iae = tracked_iae(row)
        if iae is not None:
            self.iae.setdefault(g, array("d")).append(iae)

    def _scatter(self, row: dict, iae: float, status: str) -> None:
        for name in self.axes:
            v = row["values"][name]
            ok = isinstance(v, (int, float)) and not isinstance(v, bool)
            self.numeric[name] = self.numeric[name] and ok
            self.scatter[name].append(float(v) if ok else math.nan)
        self.scatter_iae.append(iae)
        self.scatter_fail.append(status == "fail")

    def _model(self, row: dict) -> None:
        q = row.get("measures", {})
        if q.get("model_mismatch") is not None and (self.model is None or q["model_mismatch"] > self.model[0]):
            self.model = (q["model_mismatch"], row["index"], row["id"])
        self.flagged += bool(q.get("model_warning"))

    def point_list(self) -> list[dict]:
        """The grid points (in the order first met), with pass fraction and IAE median and 95th percentile."""
        out = []
        for g, p in self.points.items():
            iae = np.frombuffer(self.iae[g]) if g in self.iae else None
            out.append(
                p
                | {
                    "pass_fraction": p["pass"] / p["runs"],
                    "iae_median": float(np.median(iae)) if iae is not None else None,
                    "iae_p95": float(np.percentile(iae, 95)) if iae is not None else None,
                }
            )
        return out


def _failure(row: dict) -> dict:
    return {k: row[k] for k in ("index", "id", "status", "values", "reasons")}


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
