"""A campaign's verdicts (one per planned run), judged from the store in plan order, and the tally the report is
drawn from, kept in numpy arrays indexed by the plan.

Each block file is judged once (:func:`.judged.judge_part`, by the cluster's worker that ran its runs, or here from
the store's columns, :meth:`.store.Store.report_part`): its runs are judged at once
(:func:`.criteria.evaluate_columns` over the typed columns; no run's JSON is decoded), and each kept run's
``campaign.csv`` status and reasons and its cells (the columns' values as text, made once a column), with the verdict's
JSON text of a run that did not pass, go, as one line, to an anonymous temporary file, and its numbers (status, IAE,
model mismatch, failed criteria) to arrays indexed by the plan's distinct runs. The planned runs are then walked in
plan order, :data:`HEAD_CHUNK` at a time: each CSV row is its head's texts (:func:`head_texts`: a generated plan's
made from each grid point's template and each draw's values' texts) and its spilled ones joined, with nothing decoded
again but the reasons of the failed runs ``failures.txt`` lists. Nothing holds every row: the client keeps an offset
and a few numbers a run, and :class:`Tally` counts from them and the plan's arrays (:func:`.plan.plan_columns`: each
run's grid point and axis values, 9 bytes an axis), not run by run. A run's whole row (its head, verdict and stored
record) is made when asked, from the store (:class:`.stored_rows.StoredRows`)."""

from __future__ import annotations

import json
import logging
import math
import os
import tempfile
from collections import Counter
from collections.abc import Iterator, Mapping
from typing import IO, Any

import numpy as np
import pyarrow as pa

from .jsontext import float_texts
from .judged import SEP, JudgedPart, csv_field, judge_part
from .plan import PlanColumns, PlannedRuns, plan_columns

log = logging.getLogger(__name__)

FAILURES_LIMIT = 200
WORST = 3
STATUSES = ("pass", "fail", "error", "missing")  # a run's status code is its place here
PASS, FAIL, ERROR, MISSING = range(4)


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


def _csv_value(value: Any) -> str:
    """An axis value as ``campaign.csv`` writes it: a string as it is, a finite float by ``repr``, else JSON."""
    if type(value) is float and math.isfinite(value):
        return float.__repr__(value)
    return csv_field(value if isinstance(value, str) else json.dumps(value))


HEAD_CHUNK = 2048  # runs whose CSV rows are made at once: their texts held together, a few hundred bytes a run


def head_texts(plan: Any, axes: list[str]) -> Iterator[tuple[list[str], list[str], list[str]]]:
    """The parts of each planned run's ``campaign.csv`` row its head gives, in plan order, :data:`HEAD_CHUNK` runs at
    a time: the three parts around the verdict's (``index,id,``; ``,`` the ``axes`` values and the seed ``,``; ``,``
    the artifact's sha256 and the line end). A generated plan's from its parts (:meth:`.plan.PlannedRuns.head_parts`):
    each grid point's and each draw's values made text once, a run's texts joined a chunk at a time."""
    parts = plan.runs.head_parts() if isinstance(plan.runs, PlannedRuns) else None
    if parts is None:
        heads = iter(plan.runs.heads() if isinstance(plan.runs, PlannedRuns) else plan.runs)
        while chunk := [h for _, h in zip(range(HEAD_CHUNK), heads)]:
            yield _point_texts(chunk, axes)
        return
    ids = plan.runs.ids
    plain = bool(np.char.isalnum(ids).all()) if len(ids) else True
    texts = _HeadTemplates(parts, axes)
    for start in range(0, len(ids), HEAD_CHUNK):
        yield texts.chunk(start, ids[start : start + HEAD_CHUNK].tolist(), plain)


def _point_texts(heads: list, axes: list[str]) -> tuple[list[str], list[str], list[str]]:
    """:func:`head_texts` of the heads ``heads``, each from its own values."""
    pre = [f"{h.index},{csv_field(h.id)}," for h in heads]
    mid = ["," + ",".join([*(_csv_value(h.values[a]) for a in axes), str(h.seed)]) + "," for h in heads]
    post = ["," + csv_field(h.artifact_sha256 or "") + "\n" for h in heads]
    return pre, mid, post


class _HeadTemplates:
    """A generated plan's CSV head texts by part: per grid point its values' cells, made once; the draws' values made
    text a chunk of runs at a time, an axis at a time (a choice's values once each), not held for every draw."""

    def __init__(self, parts: Any, axes: list[str]) -> None:
        self.parts = parts
        self.csv_drawn = [a for a in axes if a in parts.drawn]  # the CSV's order
        self.csv_mid = ["," + "".join(_csv_value(grid[a]) + "," for a in axes if a in grid) for grid in parts.grid]
        self.shas = ["," + csv_field(sha or "") + "\n" for sha in parts.shas]
        self.choices = {name: [_csv_value(v) for v in values] for name, values in parts.choices.items()}

    def _draws(self, js: np.ndarray) -> list[str]:
        """Draws ``js``' values as their CSV cells with the seed (a comma after), an axis at a time: a number's text is
        its ``repr`` (:func:`.jsontext.float_texts`; a value that is not finite: JSON's text, as a head's)."""
        texts: dict[str, list[str]] = {}
        for name in self.csv_drawn:
            column = self.parts.drawn[name]
            if name in self.choices:
                words = self.choices[name]
                texts[name] = [words[c] for c in column[js].astype(int).tolist()]
                continue
            x = column[js].astype(float)
            numbers = x.tolist()
            texts[name] = float_texts(numbers, pa.array(x)) if np.isfinite(x).all() else list(map(_csv_value, numbers))
        seeds = list(map(str, self.parts.seeds[js].tolist()))
        return [",".join(row) + "," for row in zip(*(texts[name] for name in self.csv_drawn), seeds)]

    def chunk(self, start: int, ids: list[bytes], plain: bool) -> tuple[list[str], list[str], list[str]]:
        """The texts of the runs from plan index ``start`` (``ids``; ``plain``: every id alphanumeric, a CSV field as
        it is), the runs of one grid point (a chunk holds one or two) joined together."""
        runs = self.parts.runs
        ks = np.arange(start, start + len(ids))
        draw_csv = self._draws(ks % runs)
        texts = [rid.decode("ascii") for rid in ids]
        pre = [f"{k},{t}," if plain else f"{k},{csv_field(t)}," for k, t in zip(ks.tolist(), texts)]
        mid, post = [], []
        gs = ks // runs
        for a, b in _spans(gs):
            g = int(gs[a])
            mid += [self.csv_mid[g] + d for d in draw_csv[a:b]]
            post += [self.shas[g]] * (b - a)
        return pre, mid, post


def _spans(values: np.ndarray) -> list[tuple[int, int]]:
    """The spans ``[a, b)`` of equal neighbours in ``values``."""
    cut = (np.flatnonzero(values[1:] != values[:-1]) + 1).tolist()
    return list(zip([0, *cut], [*cut, len(values)]))


MISSING_VERDICT = {"status": "missing", "failed": ["missing"], "reasons": ["no result"]}


FIXED_CELLS = 8


class Verdicts:
    """Every stored run's verdict, its ``campaign.csv`` texts spilled to an anonymous temporary file (gone when
    closed); its numbers in arrays indexed by the plan's distinct runs (``ids``, ASCII bytes in plan order; a run
    planned twice is one run). The tracked outputs and outputs the runs report are the CSV's columns.

    Filled a block file at a time: by :meth:`add`, a block a cluster's worker judged as it ran it (while the campaign
    runs), then by :meth:`complete`, which judges here every other block file of the store."""

    def __init__(self, criteria: Any, ids: np.ndarray) -> None:
        self.against = criteria  # what the runs are judged against (self.criteria: the names of those failed)
        self.file: IO[bytes] = tempfile.TemporaryFile()
        self.uids, self.slot = np.unique(ids, return_inverse=True)
        self._empty()

    def _empty(self) -> None:
        """No run judged yet: every run missing, the spill empty."""
        n = len(self.uids)
        self.file.seek(0)
        self.file.truncate()
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
        self.ahead: dict[str, np.ndarray] = {}  # the block files :meth:`add` took: their runs' ids
        self._flushed = False
        self._forms: dict[tuple, tuple[int, int]] = {}

    def add(self, name: str, judged: JudgedPart) -> None:
        """Take the runs of block file ``name`` as judged elsewhere (:func:`~.judged.judge_part`: by the worker that
        ran them), as the file is stored; :meth:`complete` checks that the store keeps their records there."""
        self.ahead[name] = judged.ids
        self._take(judged)

    def complete(self, store: Any) -> Verdicts:
        """Judge here the runs of every block file of ``store`` :meth:`add` did not take, and return this. When the
        store does not keep the records of every run of a file taken ahead there (a run stored again since, in
        another file), every run is judged again from the store: a verdict is the record's the store keeps."""
        if not all(store.keeps_all(name, ids) for name, ids in self.ahead.items()):
            log.info("the verdicts judged on the workers are not all of the records stored: judged again here")
            self._empty()
        for path in store.files():
            if path.name not in self.ahead and (part := store.report_part(path)) is not None:
                self._take(judge_part(part, self.against))
        return self

    def _take(self, judged: JudgedPart) -> None:
        """File the runs of ``judged`` the plan holds in: their numbers set at once and their lines written in one call
        (a write a run: 18 us of each, profiled)."""
        n = len(self.uids)
        slots = np.minimum(np.searchsorted(self.uids, judged.ids), max(n - 1, 0))
        planned = self.uids[slots] == judged.ids if n else np.zeros(len(judged.ids), bool)
        rows = np.flatnonzero(planned)
        if not len(rows):
            return
        lines, sizes = (judged.lines, judged.sizes) if len(rows) == len(judged.ids) else _lines_of(judged, rows)
        u = slots[rows]
        self.at[u] = self.file.tell() + np.cumsum(sizes) - sizes
        self.size[u] = sizes
        self.file.write(lines)
        forms = [self._form(key) for key in judged.forms]
        codes = np.array([*(c for c, _ in forms), PASS], np.int8)  # a run that passed (form -1): the last
        masks = np.array([*(m for _, m in forms), 0], np.int64)
        form = judged.form[rows]
        self.shape[u], self.code[u], self.failed[u] = self._shapes(judged, rows)[rows], codes[form], masks[form]
        self.iae[u], self.model[u], self.warning[u] = judged.iae[rows], judged.model[rows], judged.warning[rows]

    def _form(self, key: tuple) -> tuple[int, int]:
        """The status code and the failed criteria's bits (into :attr:`criteria`, noted in the order first met) of the
        verdicts of form ``key`` (:func:`~.judged.verdict_form`), made once."""
        if key in self._forms:
            return self._forms[key]
        status, names, _ = key
        mask = 0
        for name in names:
            if name not in self.criteria:
                self.criteria.append(name)
            mask |= 1 << self.criteria.index(name)
        self._forms[key] = STATUSES.index(status), mask
        return self._forms[key]

    def _shapes(self, part: Any, rows: np.ndarray) -> np.ndarray:
        """Each run's (tracked outputs, outputs) as a number into :attr:`shapes`, the planned ``rows``' named in the
        CSV's columns."""
        numbers = np.zeros(len(part.shapes), np.int16)
        for s in np.unique(part.shape[rows]).tolist():
            names = part.shapes[s]
            if names not in self.shapes:
                self.shapes.append(names)
                self.tracked.update(names[0])
                self.outputs.update(names[1])
            numbers[s] = self.shapes.index(names)
        return numbers[part.shape]

    def text(self, u: int) -> tuple[str, str, str]:
        """Run ``u``'s verdict as JSON text (empty for a run that passed), its CSV status and reasons, and its CSV
        cells after them in its own tracked outputs and outputs (:data:`MISSING_VERDICT` without a record)."""
        at = int(self.at[u])
        if at < 0:
            return self._missing
        body, verdict, cells, _ = self._read(at, int(self.size[u])).split(SEP)
        return body, verdict, cells

    def _read(self, at: int, size: int) -> str:
        """``size`` bytes of the spill from ``at``, as text: by ``os.pread``, not a seek and a buffered read; not a
        memory map either, whose pages read would count in the client's resident memory (the spill of 100,000 runs
        is ~220 MB)."""
        if not self._flushed:  # the spill is written whole before the first read
            self.file.flush()
            self._flushed = True
        return os.pread(self.file.fileno(), size, at).decode("utf-8")

    _missing = (json.dumps(MISSING_VERDICT, sort_keys=True), "missing,no result", "," * (FIXED_CELLS - 2))

    def rows(self, slots: list[int], tracked: list[str], outs: list[str]) -> tuple[list[str], list[str]]:
        """The CSV status and reasons and the cells of each of runs ``slots`` (:meth:`text`'s), the cells in the
        columns ``tracked`` and ``outs`` (sorted) of every run. The runs whose lines follow each other in the spill (a
        block's, in plan order: most of a chunk) are read by one ``pread`` and split at once."""
        if not slots:
            return [], []
        at, size = self.at[slots], self.size[slots]
        fields: list[str] = []
        # a span of lines: where the next run's line starts where this one's ends (a missing run is a span alone)
        cut = np.flatnonzero((at[1:] != at[:-1] + size[:-1]) | (at[1:] < 0) | (at[:-1] < 0)) + 1
        for a, b in zip([0, *cut.tolist()], [*cut.tolist(), len(slots)]):
            if at[a] < 0:
                fields.extend(self._missing)
            else:
                fields.extend(self._read(int(at[a]), int(size[a:b].sum())).split(SEP)[:-1])
        verdicts, cells = fields[1::3], fields[2::3]
        every = (tuple(tracked), tuple(outs))
        plain = np.array([names == every for names in self.shapes] or [True], bool)[self.shape[slots]] & (at >= 0)
        for n in np.flatnonzero(~plain).tolist():
            cells[n] = self.cells(slots[n], cells[n], tracked, outs)
        return verdicts, cells

    def cells(self, u: int, cells: str, tracked: list[str], outs: list[str]) -> str:
        """Run ``u``'s CSV cells (``cells``: after its reasons, in its own tracked outputs and outputs) in the columns
        ``tracked`` and ``outs`` (sorted) of every run (the cells are numbers: no comma)."""
        own_tracked, own_outs = self.shapes[self.shape[u]] if self.at[u] >= 0 else ((), ())
        split = cells.split(",")
        fixed, rest = split[: FIXED_CELLS - 1], split[FIXED_CELLS - 1 :]
        by_t = {t: rest[3 * i : 3 * i + 3] for i, t in enumerate(own_tracked)}
        by_o = {o: rest[3 * len(own_tracked) + i] for i, o in enumerate(own_outs)}
        return ",".join(
            [*fixed, *(c for t in tracked for c in by_t.get(t, ["", "", ""])), *(by_o.get(o, "") for o in outs)]
        )

    def close(self) -> None:
        self.file.close()


class Tally:
    """What the report says of the rows, from arrays in plan order: each planned run's status, IAE and failed criteria
    (:class:`Verdicts`' arrays) and its grid point and axis values (the plan's, :func:`~.plan.plan_columns`).
    :meth:`finish` makes the counts by status and by failed criterion, each grid point's counts and IAE median and
    95th percentile (numpy's exact ones), the :data:`FAILURES_LIMIT` worst failed runs, the worst runs, the largest
    model mismatch, the finished runs' pass/fail (the envelopes' runs) and the scatter plot's coordinates (an axis is
    plotted when every run's value is a number)."""

    def __init__(self, plan: Any, verdicts: Verdicts) -> None:
        self.plan, self.verdicts = plan, verdicts
        self.grid_names = [a.name for a in plan.campaign.grid]
        self.axes = [a.name for a in (*plan.campaign.draws, *plan.campaign.grid)]
        self.runs = 0

    def finish(self, ids: np.ndarray) -> None:
        """The tallies of the plan's runs (``ids``: theirs, in plan order, ASCII bytes)."""
        v, slot = self.verdicts, self.verdicts.slot[: len(ids)]
        code, iae = v.code[slot], v.iae[slot]
        self.runs = len(ids)
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
        distinct = np.zeros(len(slot), bool)  # a run planned twice: where it is first (its slot's first place)
        distinct[np.unique(slot, return_index=True)[1]] = True
        seen = finished & distinct
        self.status = RunStatus(ids[seen], code[seen] == FAIL, plan_draws(self.plan)[seen])
        columns = plan_columns(self.plan)
        self._points(columns, code, iae)
        self._scatter(columns, code, iae)
        self.bad = int((code != PASS).sum())
        self._failure_rows = self._failures(code, iae, slot)

    def _failed_counts(self, masks: np.ndarray) -> Counter:
        """Runs failing each criterion, most first (ties: the criterion met first in plan order, as a Counter fed
        row by row gives them)."""
        found = []
        for bit, name in enumerate(self.verdicts.criteria):
            hit = (masks >> bit) & 1 == 1
            if hit.any():
                found.append((-int(hit.sum()), int(hit.argmax()), name))
        return Counter({name: -n for n, _, name in sorted(found)})

    def _points(self, columns: PlanColumns, code: np.ndarray, iae: np.ndarray) -> None:
        self.point_rows = []
        for g, values in columns.grid_values.items():
            mine = columns.grid == g
            c = np.bincount(code[mine], minlength=4)
            runs = int(mine.sum())
            vals = iae[mine & ~np.isnan(iae)]
            self.point_rows.append(
                {"grid_index": g, "values": values, "runs": runs, "pass": int(c[PASS]), "fail": int(c[FAIL]),
                 "error": int(c[ERROR] + c[MISSING]), "pass_fraction": int(c[PASS]) / runs,
                 "iae_median": float(np.median(vals)) if vals.size else None,
                 "iae_p95": float(np.percentile(vals, 95)) if vals.size else None}
            )  # fmt: skip

    def _scatter(self, columns: PlanColumns, code: np.ndarray, iae: np.ndarray) -> None:
        """The scatter plot's runs (those with an IAE): their IAE, whether each failed, and each axis's values (NaN
        where not a number; ``numeric``: whether every one is)."""
        has = ~np.isnan(iae)
        self.scatter_iae, self.scatter_fail = iae[has], code[has] == FAIL
        self.numeric = {name: bool(columns.numeric[name][has].all()) for name in self.axes}
        self.scatter = {
            name: np.where(columns.numeric[name][has], columns.numbers[name][has], math.nan) for name in self.axes
        }

    def point_list(self) -> list[dict]:
        """The grid points (in the order first met), with pass fraction and IAE median and 95th percentile."""
        return self.point_rows

    def failure_rows(self) -> list[dict]:
        """The :data:`FAILURES_LIMIT` worst failed runs (index, id, status, values, reasons), worst first; errors
        last."""
        return self._failure_rows

    def _failures(self, code: np.ndarray, iae: np.ndarray, slot: np.ndarray) -> list[dict]:
        """The :data:`FAILURES_LIMIT` worst runs that did not pass: failed ones by IAE, largest first (one without an
        IAE, or of 0, first of all), then errors and missing runs; ties in plan order. Their reasons: the only
        verdicts read again."""
        bad = np.flatnonzero(code != PASS)
        fail = code[bad] == FAIL
        known = fail & (iae[bad] != 0) & ~np.isnan(iae[bad])
        by_iae = np.where(known, -np.where(known, iae[bad], 0.0), np.where(fail, -math.inf, 0.0))
        out = []
        for k in bad[np.lexsort((bad, by_iae, ~fail))][:FAILURES_LIMIT].tolist():
            head = self.plan.runs.head(k) if isinstance(self.plan.runs, PlannedRuns) else self.plan.runs[k]
            reasons = json.loads(self.verdicts.text(int(slot[k]))[0])["reasons"]
            out.append({"index": head.index, "id": head.id, "status": STATUSES[code[k]], "values": head.values,
                        "reasons": reasons})  # fmt: skip
        return out


def plan_ids(plan: Any) -> np.ndarray:
    """The plan's run ids in plan order, ASCII bytes."""
    if isinstance(plan.runs, PlannedRuns):
        return plan.runs.ids
    return np.array([p.id.encode("ascii") for p in plan.runs], dtype="S")


def plan_draws(plan: Any) -> np.ndarray:
    """Each planned run's draw, its place among its grid point's runs (a generated plan's run ``k``: ``k % runs``)."""
    if isinstance(plan.runs, PlannedRuns):
        return np.arange(len(plan.runs)) % max(plan.campaign.runs, 1)
    return np.array([p.draw for p in plan.runs], np.int64)


class RunStatus(Mapping):
    """Run id -> ``pass`` or ``fail``, held as arrays: the ids (ASCII bytes, distinct), whether each failed and each
    one's draw (:func:`plan_draws`)."""

    def __init__(self, ids: np.ndarray, failed: np.ndarray, draws: np.ndarray) -> None:
        self.ids, self.failed, self.draws = ids, failed, draws

    def __len__(self) -> int:
        return len(self.ids)

    def __iter__(self) -> Iterator[str]:
        return (i.decode("ascii") for i in self.ids.tolist())

    def __getitem__(self, run_id: str) -> str:
        hit = np.flatnonzero(self.ids == run_id.encode("ascii", "replace"))
        if not hit.size:
            raise KeyError(run_id)
        return "fail" if self.failed[hit[0]] else "pass"


def _lines_of(judged: JudgedPart, rows: np.ndarray) -> tuple[bytes, np.ndarray]:
    """The spilled lines of the runs ``rows`` of ``judged`` and their sizes."""
    starts = np.cumsum(judged.sizes) - judged.sizes
    sizes = judged.sizes[rows]
    return b"".join(judged.lines[a : a + b] for a, b in zip(starts[rows].tolist(), sizes.tolist())), sizes
