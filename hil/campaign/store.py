"""A campaign folder: inputs (artifacts and FMUs by sha256, the plan) and one Parquet file per block of runs.

::

    DIR/plan.json                 the campaign, its runs' ids in plan order and their sha256
    DIR/artifacts/<sha256>.json DIR/fmus/<sha256>.fmu        what travelled to the workers
    DIR/blocks/<address>.parquet  one block of runs (a Dask task's), one row per run (:data:`.block_layout.SCHEMA`,
                                  then :func:`.block_columns.row_columns`)
    DIR/campaign.json campaign.csv summary.txt *.png        the merged report (see report.py)

A block file's name is its content address (:func:`.block_layout.block_address`: the sha256 of its runs' ids, each
itself the hash of the run's inputs and gainlink's version), so the same runs always land in the same file. A row holds
the run's id, its status (``done`` or ``error``), its record's free-form parts as compact JSON texts (``record``:
inputs, link, an error's reason; ``metrics``: the run's metrics), its report row's typed values as typed columns
(:func:`.block_columns.row_columns`: ``complete``, the run's own reason, the measures, the worker; what the verdict and
``campaign.csv`` read: the report decodes no JSON of a result), not again as JSON: the row's text, which a run's row
gives, is made from them (:func:`.block_texts.row_texts`; ``row`` holds it whole only for a row they cannot give
exactly, :func:`.block_columns.given_row`), and its traces downsampled to at most ``worker.MAX_TRACE_POINTS`` evenly
spaced true samples (first and last kept; each a binary value, the run's float32 values in C order: ``t``, and ``y``,
``u``, ``r`` row by row with their widths, so a batch of runs is read as one numpy array over the column's buffer,
:func:`_flat`); the full trace of a run is not stored, it is replayed (``gainlink campaign show DIR --run ID``). The
file's schema metadata names the gainlink version, the campaign that wrote it and the file's layout
(:data:`.block_layout.LAYOUT`): a folder holding another's blocks, or blocks of an earlier layout, is refused in one
line on resume (:func:`refuse_foreign`).

A worker that sees the campaign folder writes its block file there itself (:func:`.block_file.write_block`); the client
notes it (:meth:`Store.took_block`) without reading it. A task whose runs all stepped in blocks is stored from the
blocks' lists (:class:`.block_columns.BlockRuns`, :func:`.block_file.encode_runs`: no record dict a run), the same table
:func:`.block_file.encode_block` makes of the runs' records; the JSON texts of a block's runs are made a structure at a
time (:mod:`.jsontext`).

A file is written to a temporary name and renamed (mode 0644 under the usual umask), so a run counts as done exactly
when a block file holds it; a campaign killed at any point resumes by running the runs no block holds, and those whose
only record is an error (an error is not a result: run the campaign again once its cause is fixed). A run recorded
twice (an error, then a result on resume) counts by its result.

This module holds the folder: its inputs, its index of which block holds which run, and what is read from it (records,
traces, the report's parts). A block file itself is made and read back by the modules below it:
:mod:`.block_layout` (its columns, layout version and name), :mod:`.block_columns` (a block's runs as typed columns),
:mod:`.block_file` (the file made on the worker) and :mod:`.block_texts` (its runs made text again when read).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from gainlink.errors import GainlinkError
from gainlink.fileio import atomic_write_bytes, atomic_write_text, prepare_output_dir
from gainlink.version import __version__

from .block_file import encode_block, with_inputs
from .block_layout import (
    FLOAT_MEASURES,
    LAYOUT,
    META_CAMPAIGN,
    META_LAYOUT,
    META_VERSION,
    METRIC_COLUMNS,
    NAMED,
    RECORD_COLUMNS,
    ROW_COLUMNS,
    TRACE_FIELDS,
    WIDE,
    block_file_name,
)
from .block_texts import cell_texts, joined, numbers_text, record_texts, row_texts, struct_fields, value_texts
from .config import CampaignError
from .criteria import RunColumns
from .plan import CampaignPlan, RunPoint


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, indent=1, allow_nan=False) + "\n"


#: Runs read at a time for the envelopes (:meth:`Store.trace_stacks`): a whole 1,000-run block's traces decoded at
#: once, with the copies made of them, took the client's peak resident memory 77 MB over its start for 10,000 runs;
#: 128 at a time, 45 MB, for the same CPU.
TRACE_BATCH = 128

#: Bytes of a block file's column read at a time for the envelopes (:meth:`Store.trace_stacks`): its pages decoded as
#: the batches need them, not its whole column chunk (a block's: one row group) read at once.
TRACE_BUFFER = 1 << 20


def _row_groups(block: pq.ParquetFile, wanted: np.ndarray) -> list[int]:
    """The row groups of the open block file ``block`` that hold one of the runs ``wanted`` (sorted, distinct), from
    its ``id`` column (a few bytes a run) and its row groups' sizes."""
    rows = np.flatnonzero(members(_ids(block.read(columns=["id"], use_threads=False).column("id")), wanted))
    ends = np.cumsum([block.metadata.row_group(g).num_rows for g in range(block.num_row_groups)])
    return np.unique(np.searchsorted(ends, rows, side="right")).tolist()


def _read(path: Path | pq.ParquetFile, columns: list[str]) -> pa.Table:
    """``columns`` of block file ``path`` (or of the file already open), after handing back to the system what
    Arrow's pool kept of the blocks read before (mimalloc keeps freed pages: +30 MB of the client's resident memory
    over 10,000 runs' records). Read by :class:`pyarrow.parquet.ParquetFile` in this thread: ``pq.read_table``'s
    dataset machinery and its thread pool cost ~10 ms of CPU a block file of the report's columns (of 834 runs),
    this ~4.5."""
    pa.default_memory_pool().release_unused()
    if isinstance(path, pq.ParquetFile):
        return path.read(columns=columns, use_threads=False)
    with pq.ParquetFile(path) as block:
        return block.read(columns=columns, use_threads=False)


TEXT_COLUMNS = ("row", *METRIC_COLUMNS)  # a row's JSON texts and its metrics' (:func:`.block_texts.row_texts`)


def _row_columns(path: Path) -> list[str]:
    """The columns of block file ``path`` :func:`.block_texts.row_texts` reads."""
    return _text_columns(set(pq.read_schema(path).names), ROW_COLUMNS)


def _text_columns(present: set[str], more: Iterable[str] = ()) -> list[str]:
    """:data:`TEXT_COLUMNS` and ``more`` of a block file whose columns are ``present`` (an earlier layout's: fewer)."""
    return [k for k in (*TEXT_COLUMNS, *more) if k in present]


def _ids(column: pa.ChunkedArray) -> np.ndarray:
    """A block's ``id`` column as ASCII bytes (numpy ``S``), as the plan's ids are."""
    return np.array(column.to_pylist(), dtype="S")


def _done(column: pa.ChunkedArray) -> np.ndarray:
    """A block's ``status`` column as whether each run has a result."""
    return pc.not_equal(column, "error").to_numpy(zero_copy_only=False)


def _wanted(ids: Iterable[str] | np.ndarray) -> np.ndarray:
    """Run ids (strings or ASCII bytes) as ASCII bytes."""
    if isinstance(ids, np.ndarray) and ids.dtype.kind == "S":
        return ids
    return np.array([i.encode("ascii", "replace") for i in ids], dtype="S")


def members(names: np.ndarray, pool: np.ndarray) -> np.ndarray:
    """Which of ``names`` are in ``pool``, a sorted array of distinct ids (``np.unique``'s): a binary search per name,
    not :func:`numpy.isin`'s sort of both (which, called for each 128 runs of a 100,000-run campaign, sorted the
    100,000 ids 790 times)."""
    if not len(pool):
        return np.zeros(len(names), bool)
    k = np.minimum(np.searchsorted(pool, names), len(pool) - 1)
    return pool[k] == names


def _flat(column: pa.ChunkedArray | pa.Array) -> np.ndarray:
    """A trace column's float32 values, its rows' one after the other: a read-only view of the column's buffer (its
    rows' bytes are contiguous in a binary array), no copy."""
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    _, offsets, data = arr.buffers()
    at = np.frombuffer(offsets, np.int64, len(arr) + 1, offset=8 * arr.offset) if offsets is not None else [0, 0]
    if data is None or at[-1] == at[0]:
        return np.zeros(0, np.float32)
    return np.frombuffer(data, np.float32, int(at[-1] - at[0]) // 4, offset=int(at[0]))


def _trace_of(table: pa.Table, row: int) -> dict[str, np.ndarray] | None:
    t = table.column("t")[row].as_py()
    if t is None:
        return None
    out = {"t": np.frombuffer(t, np.float32).copy()}
    for k in WIDE:
        width = table.column(f"{k}_width")[row].as_py()
        out[k] = np.frombuffer(table.column(k)[row].as_py(), np.float32).reshape(out["t"].size, width).copy()
    return out


def refuse_foreign(out: str | Path, plan_doc: dict) -> None:
    """Refuse, in one line and before anything is written, to resume into ``out`` when its ``plan.json`` or one of
    its block files is another campaign's (another name) or another gainlink version's (its runs would be ignored,
    not resumed), when it stored other runs' traces (``traces``), or when it holds the per-run result files of an
    earlier gainlink (``runs/``)."""
    out = Path(out)
    path = out / "plan.json"
    if (out / "runs").is_dir():
        raise CampaignError(
            f"campaign: {out} holds per-run results (runs/) of an earlier gainlink, which this one does not read: "
            "give another --out"
        )
    if not path.is_file():
        return
    try:
        old = json.loads(path.read_text("utf-8"))["campaign"]
        name, version = old["name"], old.get("gainlink")
    except (OSError, ValueError, KeyError, TypeError):
        raise CampaignError(
            f"campaign: {path} is not a campaign plan this gainlink can read; give another --out"
        ) from None
    _refuse(out, name, version, plan_doc["campaign"]["name"])
    kept, wanted = old.get("traces"), plan_doc["campaign"].get("traces")
    if kept is not None and kept != wanted:  # the runs reused would not hold the traces this campaign stores
        raise CampaignError(f"campaign: {out} stores traces = {kept!r}, this campaign {wanted!r}: give another --out")
    for block in sorted((out / "blocks").glob("*.parquet")) if (out / "blocks").is_dir() else ():
        try:
            meta = pq.read_schema(block).metadata or {}
        except (OSError, pa.ArrowException):
            raise CampaignError(
                f"campaign: {block} is not a block file this gainlink can read; give another --out"
            ) from None
        got = {k: v.decode("utf-8") for k, v in meta.items() if k in (META_VERSION, META_CAMPAIGN, META_LAYOUT)}
        _refuse(block, got.get(META_CAMPAIGN, "?"), got.get(META_VERSION), plan_doc["campaign"]["name"])
        if got.get(META_LAYOUT) != LAYOUT:
            raise CampaignError(
                f"campaign: {block} is a block file of an earlier layout (before {LAYOUT}) than this gainlink's: "
                "its runs would not be reused; give another --out"
            )


def _refuse(where: Path, name: str, version: str | None, new: str) -> None:
    if name != new:
        raise CampaignError(f"campaign: {where} holds campaign {name!r}, not {new!r}: give another --out")
    if version != __version__:
        raise CampaignError(
            f"campaign: {where} was written by gainlink {version or 'older than 0.1.0'}, this is {__version__}: "
            "its runs would not be reused; give another --out"
        )


class Store:
    """The campaign folder ``out`` (created on demand) and its block files.

    Its index of the stored runs is numpy arrays, not a dict by run id (100,000 runs: 2.4 MB, not ~20): each run's id
    (ASCII bytes), whether its kept record is a result, and the number of the block file holding it; one part a block
    as blocks arrive, resolved (sorted by id, one row a run) when asked."""

    def __init__(self, out: str | Path, *, campaign: str = "") -> None:
        self.out = prepare_output_dir(out)
        self.blocks = self.out / "blocks"
        self.campaign = campaign
        self._names: list[str] = []  # block file names, by number
        self._number: dict[str, int] = {}
        self._parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # ids, done, block number: in arrival order
        self._resolved: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._loaded = False

    def prepare(self, plan: CampaignPlan, *, plan_doc: dict) -> None:
        """Write the inputs: artifacts, FMUs and ``plan.json``; make the ``blocks`` folder, and remove from it the
        temporary files of block files an earlier run of the folder did not finish writing (a worker ended by a
        Ctrl-C, or killed, while it wrote one: those runs are run again)."""
        for folder, items, ext in (("artifacts", plan.artifacts, "json"), ("fmus", plan.blobs, "fmu")):
            if items:
                (self.out / folder).mkdir(exist_ok=True)
            for sha, data in items.items():
                path = self.out / folder / f"{sha}.{ext}"
                if not path.is_file():
                    atomic_write_bytes(path, data)
        atomic_write_text(self.out / "plan.json", _json(plan_doc))
        self.blocks.mkdir(exist_ok=True)
        for unfinished in self.blocks.glob(".*.parquet.*.tmp"):  # fileio.atomic_writer's temporary names
            unfinished.unlink(missing_ok=True)

    def files(self) -> list[Path]:
        """The block files, by name."""
        return sorted(self.blocks.glob("*.parquet"))

    def _load(self) -> None:
        """Read the ``id`` and ``status`` columns of each block file on disk, once, one file at a time."""
        if self._loaded:
            return
        self._loaded = True
        for path in self.files():
            table = _read(path, columns=["id", "status"])
            self._note(_ids(table.column("id")), _done(table.column("status")), path.name)

    def _note(self, ids: np.ndarray, done: np.ndarray, name: str) -> None:
        self._load()
        if name not in self._number:  # a block written again (the same runs) keeps its number
            self._number[name] = len(self._names)
            self._names.append(name)
        self._parts.append((ids, done, np.full(len(ids), self._number[name], np.int32)))
        self._resolved = None

    def _table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every stored run once, sorted by id: ``(ids, done, block number)``. A run stored more than once keeps its
        first result, else its last error (an error is run again; a result counts over an earlier error)."""
        self._load()
        if self._resolved is None:
            if not self._parts:
                return np.zeros(0, "S1"), np.zeros(0, bool), np.zeros(0, np.int32)
            ids, done, block = (np.concatenate(col) for col in zip(*self._parts))
            seq = np.arange(len(ids))
            order = np.lexsort((np.where(done, seq, -seq), ~done, ids))
            ids, done, block = ids[order], done[order], block[order]
            first = np.ones(len(ids), bool)
            first[1:] = ids[1:] != ids[:-1]
            self._resolved = ids[first], done[first], block[first]
            self._parts = [self._resolved]
        return self._resolved

    def _find(self, run_id: str) -> tuple[bool, str] | None:
        """(whether a result, block file name) of run ``run_id``, ``None`` without a record."""
        ids, done, block = self._table()
        key = run_id.encode("ascii", "replace")
        k = int(np.searchsorted(ids, key))
        if k == len(ids) or ids[k] != key:
            return None
        return bool(done[k]), self._names[block[k]]

    def where(self, run_id: str) -> Path | None:
        """The block file holding the record of run ``run_id`` the index keeps, ``None`` without a record."""
        hit = self._find(run_id)
        return None if hit is None else self.blocks / hit[1]

    def _kept(self, path: Path, ids: np.ndarray, *, results: bool = False) -> np.ndarray:
        """Which rows of block file ``path`` (run ``ids``) hold the record the index keeps (``results``: and it is a
        result)."""
        table_ids, done, block = self._table()
        k = np.minimum(np.searchsorted(table_ids, ids), max(len(table_ids) - 1, 0))
        if not len(table_ids):
            return np.zeros(len(ids), bool)
        number = self._number.get(path.name, -1)
        hit = (table_ids[k] == ids) & (block[k] == number)
        return hit & done[k] if results else hit

    def index(self) -> dict[str, tuple[str, str]]:
        """Every stored run: id -> (status, block file name), a result before an error; a dict made when asked, for
        a few runs' checks (the store itself keeps arrays)."""
        ids, done, block = self._table()
        return {
            i.decode("ascii"): ("done" if d else "error", self._names[b]) for i, d, b in zip(ids.tolist(), done, block)
        }

    def has(self, run_id: str) -> bool:
        """True when run ``run_id`` has a record (a result or an error)."""
        return self._find(run_id) is not None

    def finished(self, run_id: str) -> bool:
        """True when run ``run_id`` has a result: a record that is not an error (errors are run again)."""
        hit = self._find(run_id)
        return hit is not None and hit[0]

    def finished_mask(self, ids: np.ndarray) -> np.ndarray:
        """:meth:`finished` of each of ``ids`` (ASCII bytes, as :attr:`.plan.PlannedRuns.ids`), as a bool array."""
        table_ids, done, _ = self._table()
        return np.isin(ids, table_ids[done])

    def put_block(self, data: bytes | pa.Buffer) -> list[dict]:
        """Store a block file made by :func:`.block_file.encode_block`; returns each run's ``id``, ``status`` and
        ``reason`` (an error's)."""
        table = pq.read_table(pa.BufferReader(data), columns=["id", "status"])
        ids, statuses = table.column("id").to_pylist(), table.column("status").to_pylist()
        name = block_file_name(ids)
        self.blocks.mkdir(exist_ok=True)
        atomic_write_bytes(self.blocks / name, data)
        self._note(_ids(table.column("id")), _done(table.column("status")), name)
        reasons: list[str | None] = [None] * len(ids)
        errors = [i for i, status in enumerate(statuses) if status == "error"]
        if errors:  # only errors' records are decoded here: a result's is the report's to read
            reasons = _error_reasons(pq.read_table(pa.BufferReader(data), columns=list(RECORD_COLUMNS)), errors)
        return [{"id": i, "status": s, "reason": r} for i, s, r in zip(ids, statuses, reasons)]

    def took_block(self, answer: dict, ids: list[str]) -> list[dict]:
        """Note a block file a worker wrote itself (``answer``: :func:`.block_file.write_block`'s, for runs ``ids``);
        returns each run's ``id``, ``status`` and ``reason`` as :meth:`put_block` does, without reading the file."""
        if answer.get("runs") != len(ids) or answer.get("block") != block_file_name(ids):
            raise GainlinkError(f"a worker wrote block {answer.get('block')!r}, not the one of these {len(ids)} runs")
        reasons: list[str | None] = [None] * len(ids)
        done = np.ones(len(ids), bool)
        for i, reason in answer["errors"]:
            reasons[i], done[i] = reason, False
        self._note(np.array(ids, dtype="S"), done, answer["block"])
        return [{"id": i, "status": "done" if r is None and d else "error", "reason": r}
                for i, d, r in zip(ids, done, reasons)]  # fmt: skip

    def put(self, points: list[RunPoint], *, kind: str, results: list[dict]) -> list[dict]:
        """Store the client's own records of ``points`` (errors: a design that failed, a task that failed) as one
        block."""
        records = [with_inputs(r, p, kind=kind) for p, r in zip(points, results)]
        return self.put_block(encode_block([p.id for p in points], records, campaign=self.campaign))

    def report_parts(self, *, rows: bool = False) -> Iterator[ReportPart]:
        """What the report reads of every stored run, one block file at a time (:meth:`report_part`)."""
        for path in self.files():
            part = self.report_part(path, rows=rows)
            if part is not None:
                yield part

    def report_part(self, path: Path, *, rows: bool = False) -> ReportPart | None:
        """What the report reads of the runs of block file ``path`` whose records the index keeps (a run stored twice:
        one record), ``None`` when it keeps none; only the errors' ``record`` text is decoded. ``rows``: with each
        run's ``row`` text (:func:`.block_texts.row_texts`: what :class:`~.stored_rows.StoredRows` gives; the report
        does not make them)."""
        with pq.ParquetFile(path) as block:  # its footer parsed once: the schema and the columns read from it
            return _report_of(block, lambda names: self._kept(path, names), rows=rows)

    def keeps_all(self, name: str, ids: np.ndarray) -> bool:
        """Whether the index keeps the records of runs ``ids`` (ASCII bytes) in block file ``name``, every one."""
        return bool(self._kept(self.blocks / name, ids).all())

    def records(self) -> Iterator[tuple[str, dict]]:
        """Every stored run's record, one block file at a time (a run stored twice: the record the index keeps)."""
        for path in self.files():
            table = _read(path, columns=["id", *RECORD_COLUMNS, *_row_columns(path)])
            names = _ids(table.column("id"))
            kept = np.flatnonzero(self._kept(path, names)).tolist()
            taken = table.take(pa.array(kept, pa.int64())) if kept else None
            rows = row_texts(taken) if taken is not None else []
            records = record_texts(taken) if taken is not None else []
            for i, record, row in zip(kept, records, rows):
                yield names[i].decode("ascii"), joined(json.loads(record), json.loads(row))

    def runs_cpu_s(self) -> float:
        """The CPU seconds of the stored runs as their workers measured each around the run (``worker.cpu_s``: a
        block's runs each their share of the block's), summed over the records the index keeps."""
        total = 0.0
        for path in self.files():
            table = _read(path, ["id", "worker"])
            kept = self._kept(path, _ids(table.column("id")))
            total += float(np.nansum(_numbers(struct_fields(table.column("worker"))["cpu_s"])[kept]))
        return total

    def traces(self, ids: Iterable[str]) -> Iterator[tuple[str, dict[str, np.ndarray]]]:
        """The stored traces of the runs ``ids`` that have a result, one block file at a time."""
        wanted = _wanted(ids)
        for path in self.files():
            table = _read(path, columns=["id", "t", *WIDE, *(f"{k}_width" for k in WIDE)])
            names = _ids(table.column("id"))
            for row in np.flatnonzero(self._kept(path, names, results=True) & np.isin(names, wanted)).tolist():
                trace = _trace_of(table, row)
                if trace is not None:
                    yield names[row].decode("ascii"), trace

    def trace_stacks(
        self, ids: Iterable[str] | np.ndarray, *, fields: tuple[str, ...] = TRACE_FIELDS
    ) -> Iterator[tuple[np.ndarray, dict[str, np.ndarray]]]:
        """The stored traces of the runs ``ids`` that have a result, a block file at a time and within it
        :data:`TRACE_BATCH` runs at a time, stacked: for each batch, the runs of one trace shape as ``(ids (ASCII
        bytes), {"t": (k, N), "y": (k, N, p), "u": ..., "r": ...})``; only ``fields`` (and ``t``) are read, of the
        block files that hold one of the runs only the row groups that do (:meth:`_row_groups`)."""
        wanted, wide = np.unique(_wanted(ids)), [k for k in WIDE if k in fields]
        columns = ["id", "t", *wide, *(f"{k}_width" for k in WIDE)]
        for path in self._holding(wanted):
            pa.default_memory_pool().release_unused()  # as _read: what the blocks before left in Arrow's pool
            with pq.ParquetFile(path, pre_buffer=False, buffer_size=TRACE_BUFFER) as block:
                groups = _row_groups(block, wanted)
                for batch in block.iter_batches(TRACE_BATCH, row_groups=groups, columns=columns) if groups else ():
                    yield from self._stacks(path, pa.Table.from_batches([batch]), wanted, wide)

    def _holding(self, wanted: np.ndarray) -> list[Path]:
        """The block files, by name, whose kept results include one of the runs ``wanted`` (sorted, distinct)."""
        table_ids, done, block = self._table()
        if not len(table_ids) or not len(wanted):
            return []
        k = np.minimum(np.searchsorted(table_ids, wanted), len(table_ids) - 1)
        numbers = np.unique(block[k[(table_ids[k] == wanted) & done[k]]])
        return sorted(self.blocks / self._names[n] for n in numbers.tolist())

    def _stacks(
        self, path: Path, table: pa.Table, wanted: np.ndarray, wide: list[str]
    ) -> Iterator[tuple[np.ndarray, dict[str, np.ndarray]]]:
        """:meth:`trace_stacks`' stacks of the runs of ``table`` (a part of block file ``path``)."""
        names = _ids(table.column("id"))
        rows = self._kept(path, names, results=True) & members(names, wanted) & table.column("t").is_valid()
        if not rows.any():
            return
        part = table if rows.all() else table.filter(pa.array(rows))
        lengths = pc.binary_length(part.column("t")).to_numpy(zero_copy_only=False) // 4
        widths = np.stack([part.column(f"{k}_width").to_numpy(zero_copy_only=False) for k in WIDE], axis=1)
        shape_of = np.column_stack([lengths, widths])
        # one shape (the usual batch): not np.unique's sort of the rows, a third of a millisecond a batch
        same = (shape_of == shape_of[0]).all()
        for shape in shape_of[:1] if same else np.unique(shape_of, axis=0):
            pick = np.flatnonzero((shape_of == shape).all(axis=1))
            one = part if pick.size == part.num_rows else part.take(pa.array(pick))
            n, size = int(shape[0]), dict(zip(WIDE, shape[1:].tolist()))
            stack = {"t": _flat(one.column("t")).reshape(len(pick), n)}
            for k in wide:
                stack[k] = _flat(one.column(k)).reshape(len(pick), n, size[k])
            yield names[rows][pick], stack

    def _row(self, run_id: str, columns: list[str]) -> tuple[pa.Table, int] | None:
        hit = self._find(run_id)
        if hit is None:
            return None
        table = pq.read_table(self.blocks / hit[1], columns=["id", *columns])
        return table, table.column("id").to_pylist().index(run_id)

    def record(self, run_id: str) -> dict:
        """The stored record of a run (KeyError when it has none)."""
        hit = self._find(run_id)
        if hit is None:
            raise KeyError(run_id)
        got = self._row(run_id, [*RECORD_COLUMNS, *_row_columns(self.blocks / hit[1])])
        assert got is not None
        table, i = got
        one = table.slice(i, 1)
        return joined(json.loads(record_texts(one)[0]), json.loads(row_texts(one)[0]))

    def trace(self, run_id: str) -> dict[str, np.ndarray] | None:
        """The stored downsampled traces of a run, if any."""
        got = self._row(run_id, ["t", *WIDE, *(f"{k}_width" for k in WIDE)])
        return None if got is None else _trace_of(*got)

    def artifact_bytes(self, sha: str) -> bytes:
        """An artifact that travelled with the campaign."""
        return (self.out / "artifacts" / f"{sha}.json").read_bytes()

    def blobs(self) -> dict[str, bytes]:
        """Every FMU that travelled with the campaign."""
        folder = self.out / "fmus"
        return {p.stem: p.read_bytes() for p in folder.glob("*.fmu")} if folder.is_dir() else {}


@dataclass(frozen=True)
class ReportPart:
    """What the report reads of some stored runs (a block file's), one entry a run: from the typed columns of
    :func:`.block_columns.row_columns`, as numpy arrays (numbers; NaN where null) and, for ``campaign.csv``'s cells,
    each column's values as JSON writes them (``null`` where null), made once for the row's text and the cells."""

    ids: np.ndarray  # ASCII bytes
    error: np.ndarray  # bool: the run's record is an error
    rows: list[str] | None  # each run's row as JSON text (:func:`.block_texts.row_texts`), when asked
    reasons: list[str | None]  # an error's reason
    keys: np.ndarray  # ``row_keys``: which of ROW_BITS each row has
    shapes: list[tuple[tuple[str, ...], tuple[str, ...]]]  # the distinct (tracked outputs, outputs) of the runs
    shape: np.ndarray  # each run's, into ``shapes``
    texts: dict[str, list[str]]  # ``complete`` and each MEASURE_CELLS measure, as JSON text
    tracked: dict[str, dict[str, list[str]]]  # per tracked output, each METRIC_CELLS value as JSON text
    outputs_final: dict[str, list[str]]  # per output, as JSON text
    model_mismatch: np.ndarray  # NaN where null
    model_warning: np.ndarray  # bool (null: False)
    judged: RunColumns  # what the criteria read (:func:`.criteria.evaluate_columns`)


def block_report_part(data: bytes | pa.Buffer) -> ReportPart:
    """What the report reads of every run of a block file's bytes (:func:`.block_file.encode_block`'s), as
    :meth:`Store.report_part` reads a stored one: for the worker that made it to judge it."""
    with pq.ParquetFile(pa.BufferReader(data)) as block:
        part = _report_of(block, None)
    assert part is not None  # every run of the file: a block holds one at least
    return part


def _report_of(
    block: pq.ParquetFile, kept_of: Callable[[np.ndarray], np.ndarray] | None, *, rows: bool = False
) -> ReportPart | None:
    """:meth:`Store.report_part` of the open block file ``block``, the runs ``kept_of`` their ids says (None: every
    run); ``None`` when it keeps none."""
    present = set(block.schema_arrow.names)
    texts = _text_columns(present) if rows else []
    table = _read(block, ["id", "status", *texts, *(k for k in ROW_COLUMNS if k in present)])
    names = _ids(table.column("id"))
    kept = np.ones(len(names), bool) if kept_of is None else kept_of(names)
    if not kept.any():
        return None
    if not kept.all():
        table = table.filter(pa.array(kept))
    error = np.asarray(pc.equal(table.column("status"), "error").to_numpy(zero_copy_only=False), bool)
    reasons: list[str | None] = [None] * table.num_rows
    if error.any():
        records = _read(block, list(RECORD_COLUMNS)).filter(pa.array(kept))
        reasons = _error_reasons(records, np.flatnonzero(error).tolist())
    return _report_part(names[kept], error, reasons, table, rows=rows)


def _error_reasons(records: pa.Table, errors: list[int]) -> list[str | None]:
    """The ``reason`` of each of rows ``errors`` of ``records`` (a block's :data:`.block_layout.RECORD_COLUMNS`), None
    for its other rows: only the errors' records made text and decoded."""
    reasons: list[str | None] = [None] * records.num_rows
    for i, text in zip(errors, record_texts(records.take(pa.array(errors, pa.int64())))):
        reasons[i] = json.loads(text).get("reason")
    return reasons


def _report_part(
    ids: np.ndarray, error: np.ndarray, reasons: list, table: pa.Table, *, rows: bool = False
) -> ReportPart:
    """A block's kept rows (``table``) as a :class:`ReportPart`; ``rows``: with their texts (``table`` holds
    :data:`TEXT_COLUMNS`)."""
    names = table.column("names").combine_chunks()
    shapes = [tuple(tuple(x) for x in json.loads(w)) for w in names.dictionary.to_pylist()]
    measures = struct_fields(table.column("measures"))
    named = {key: struct_fields(table.column(key)) if key in table.column_names else {} for key in NAMED}
    tracked = {name: struct_fields(col) for name, col in named["tracked"].items()}
    present = {name: np.asarray(col.is_valid().to_numpy(zero_copy_only=False), bool)
               for name, col in named["tracked"].items()}  # fmt: skip
    judged = RunColumns(
        stable=np.array([x is True for x in measures["stable"].to_pylist()], bool),
        unstable_reason=measures["unstable_reason"].to_pylist(),
        longest_saturation_s=_numbers(measures["longest_saturation_s"]),
        twin_output_deviation=_numbers(measures["twin_output_deviation"]),
        output_min={k: _numbers(v) for k, v in named["output_min"].items()},
        output_max={k: _numbers(v) for k, v in named["output_max"].items()},
        tracked={k: {m: _numbers(v) for m, v in cols.items()} | {"present": present[k]} for k, cols in tracked.items()},
    )
    texts = cell_texts(table)  # the cells' texts of the measures, made once for the cells and a row's text
    return ReportPart(
        ids=ids,
        error=error,
        rows=row_texts(table, value_texts(table, texts)) if rows else None,
        reasons=reasons,
        keys=table.column("row_keys").to_numpy(),
        shapes=shapes,
        shape=names.indices.to_numpy(zero_copy_only=False),
        texts={k: texts[k] for k in ("complete", "stable", *FLOAT_MEASURES)},
        tracked={k: _metric_texts(cols) for k, cols in tracked.items()},
        outputs_final={k: numbers_text(v) for k, v in named["outputs_final"].items()},
        model_mismatch=_numbers(measures["model_mismatch"]),
        model_warning=np.asarray(pc.fill_null(measures["model_warning"], False).to_numpy(zero_copy_only=False), bool),
        judged=judged,
    )


def _metric_texts(fields: dict[str, pa.Array]) -> dict[str, list[str]]:
    """A tracked output's metrics as JSON text, each value made text once (a settling time, a whole number of samples,
    repeats: its distinct values once each)."""
    return {m: numbers_text(v, repeated=m == "settling_time_s") for m, v in fields.items()}


def _numbers(arr: pa.Array) -> np.ndarray:
    """A float64 column as numpy, NaN where null."""
    return np.asarray(arr.to_numpy(zero_copy_only=False), np.float64)
