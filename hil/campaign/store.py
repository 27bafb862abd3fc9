"""A campaign folder: inputs (artifacts and FMUs by sha256, the plan) and one Parquet file per block of runs.

::

    DIR/plan.json                 the campaign, its runs' ids in plan order and their sha256
    DIR/artifacts/<sha256>.json DIR/fmus/<sha256>.fmu        what travelled to the workers
    DIR/blocks/<address>.parquet  one block of runs (a Dask task's), one row per run (:data:`SCHEMA`)
    DIR/campaign.json campaign.csv summary.txt *.png        the merged report (see report.py)

A block file's name is its content address (:func:`block_address`: the sha256 of its runs' ids, each itself the hash
of the run's inputs and gainlink's version), so the same runs always land in the same file. A row holds the run's id,
its status (``done`` or ``error``), its record as compact JSON (inputs, reasons, metrics, measures, link, worker) and
its traces downsampled to at most ``worker.MAX_TRACE_POINTS`` evenly spaced true samples (first and last kept; float32
``t``, and ``y``, ``u``, ``r`` flattened row by row with their widths); the full trace of a run is not stored, it is
replayed (``gainlink campaign show DIR --run ID``). The file's schema metadata names the gainlink version and the
campaign that wrote it: a folder holding another's blocks is refused in one line on resume (:func:`refuse_foreign`).

A file is written to a temporary name and renamed (mode 0644 under the usual umask), so a run counts as done exactly
when a block file holds it; a campaign killed at any point resumes by running the runs no block holds, and those whose
only record is an error (an error is not a result: run the campaign again once its cause is fixed). A run recorded
twice (an error, then a result on resume) counts by its result.
"""

from __future__ import annotations

import hashlib
import io
import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from gainlink.fileio import atomic_write_bytes, atomic_write_text, prepare_output_dir
from gainlink.version import __version__

from .config import CampaignError
from .plan import CampaignPlan, RunPoint

TRACE_FIELDS = ("t", "y", "u", "r")
WIDE = ("y", "u", "r")
SCHEMA = pa.schema(
    [
        ("id", pa.string()),
        ("status", pa.string()),
        ("record", pa.string()),
        ("t", pa.list_(pa.float32())),
        *((k, pa.list_(pa.float32())) for k in WIDE),
        *((f"{k}_width", pa.int32()) for k in WIDE),
    ]
)
META_VERSION, META_CAMPAIGN = b"gainlink.version", b"gainlink.campaign"


def encode_trace(t: np.ndarray, y: np.ndarray, u: np.ndarray, r: np.ndarray) -> bytes:
    """A run's traces as the bytes of one ``.npy`` file: a structured float32 array of ``N`` samples with
    fields ``t`` (time), ``y`` (N x p outputs), ``u`` (N x m commands), ``r`` (N x q references).

    How a worker's record carries its traces to the block's table (:func:`encode_block`).
    """
    cols = {"t": np.asarray(t, np.float32).reshape(-1)}
    cols.update({k: np.asarray(v, np.float32).reshape(cols["t"].size, -1) for k, v in (("y", y), ("u", u), ("r", r))})
    table = np.empty(cols["t"].size, dtype=[("t", "<f4")] + [(k, "<f4", (cols[k].shape[1],)) for k in "yur"])
    for k, v in cols.items():
        table[k] = v
    buf = io.BytesIO()
    np.save(buf, table, allow_pickle=False)
    return buf.getvalue()


def decode_trace(data: bytes | io.BufferedIOBase) -> dict[str, np.ndarray]:
    """The traces of :func:`encode_trace` (bytes or a binary file) as ``{"t": (N,), "y": (N, p), ...}``."""
    table = np.load(io.BytesIO(data) if isinstance(data, bytes) else data, allow_pickle=False)
    return {k: np.ascontiguousarray(table[k]) for k in TRACE_FIELDS}


def _compact_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, indent=1, allow_nan=False) + "\n"


def block_address(run_ids: Iterable[str]) -> str:
    """The content address of a block (hex, 24 characters): the sha256 of gainlink's version and its runs' ids."""
    body = "\n".join([__version__, *run_ids])
    return hashlib.sha256(body.encode("ascii")).hexdigest()[:24]


def encode_block(ids: list[str], records: list[dict], *, campaign: str) -> bytes:
    """The Parquet file of a block: one row per run (``records[i]`` is run ``ids[i]``'s, its traces as
    :func:`encode_trace` bytes under ``trace``). Made on the worker, so the client only writes bytes."""
    cols: dict[str, list] = {name: [] for name in SCHEMA.names}
    for run_id, record in zip(ids, records):
        cols["id"].append(run_id)
        cols["status"].append(record["status"])
        cols["record"].append(_compact_json({k: v for k, v in record.items() if k != "trace"} | {"id": run_id}))
        trace = decode_trace(record["trace"]) if record.get("trace") is not None else None
        cols["t"].append(None if trace is None else trace["t"])
        for k in WIDE:
            cols[k].append(None if trace is None else trace[k].reshape(-1))
            cols[f"{k}_width"].append(None if trace is None else trace[k].shape[1])
    arrays = [pa.array(cols[f.name], type=f.type) for f in SCHEMA]
    meta = {META_VERSION: __version__.encode(), META_CAMPAIGN: campaign.encode("utf-8")}
    table = pa.Table.from_arrays(arrays, schema=SCHEMA.with_metadata(meta))
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    return sink.getvalue().to_pybytes()


def _trace_of(table: pa.Table, row: int) -> dict[str, np.ndarray] | None:
    t = table.column("t")[row].values
    if t is None:
        return None
    out = {"t": t.to_numpy(zero_copy_only=False)}
    for k in WIDE:
        width = table.column(f"{k}_width")[row].as_py()
        flat = table.column(k)[row].values.to_numpy(zero_copy_only=False)
        out[k] = flat.reshape(out["t"].size, width)
    return out


def refuse_foreign(out: str | Path, plan_doc: dict) -> None:
    """Refuse, in one line and before anything is written, to resume into ``out`` when its ``plan.json`` or one of
    its block files is another campaign's (another name) or another gainlink version's (its runs would be ignored,
    not resumed), or when it holds the per-run result files of an earlier gainlink (``runs/``)."""
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
    for block in sorted((out / "blocks").glob("*.parquet")) if (out / "blocks").is_dir() else ():
        try:
            meta = pq.read_schema(block).metadata or {}
        except (OSError, pa.ArrowException):
            raise CampaignError(
                f"campaign: {block} is not a block file this gainlink can read; give another --out"
            ) from None
        got = {k: v.decode("utf-8") for k, v in meta.items() if k in (META_VERSION, META_CAMPAIGN)}
        _refuse(block, got.get(META_CAMPAIGN, "?"), got.get(META_VERSION), plan_doc["campaign"]["name"])


def _refuse(where: Path, name: str, version: str | None, new: str) -> None:
    if name != new:
        raise CampaignError(f"campaign: {where} holds campaign {name!r}, not {new!r}: give another --out")
    if version != __version__:
        raise CampaignError(
            f"campaign: {where} was written by gainlink {version or 'older than 0.1.0'}, this is {__version__}: "
            "its runs would not be reused; give another --out"
        )


class Store:
    """The campaign folder ``out`` (created on demand) and its block files."""

    def __init__(self, out: str | Path, *, campaign: str = "") -> None:
        self.out = prepare_output_dir(out)
        self.blocks = self.out / "blocks"
        self.campaign = campaign
        self._index: dict[str, tuple[str, str]] | None = None  # run id -> (status, block file name)

    def prepare(self, plan: CampaignPlan, *, plan_doc: dict) -> None:
        """Write the inputs: artifacts, FMUs and ``plan.json``."""
        for folder, items, ext in (("artifacts", plan.artifacts, "json"), ("fmus", plan.blobs, "fmu")):
            if items:
                (self.out / folder).mkdir(exist_ok=True)
            for sha, data in items.items():
                path = self.out / folder / f"{sha}.{ext}"
                if not path.is_file():
                    atomic_write_bytes(path, data)
        atomic_write_text(self.out / "plan.json", _json(plan_doc))

    def files(self) -> list[Path]:
        """The block files, by name."""
        return sorted(self.blocks.glob("*.parquet"))

    def index(self) -> dict[str, tuple[str, str]]:
        """Every stored run: id -> (status, block file name), a result before an error (read once: the ``id`` and
        ``status`` columns of each block, one file at a time)."""
        if self._index is None:
            self._index = {}
            for path in self.files():
                cols = pq.read_table(path, columns=["id", "status"]).to_pydict()
                self._note(cols["id"], cols["status"], path.name)
        return self._index

    def _note(self, ids: list[str], statuses: list[str], name: str) -> None:
        index = self.index() if self._index is None else self._index
        entries = {status: (status, name) for status in set(statuses)}  # one tuple a status and block, not a run
        for run_id, status in zip(ids, statuses):
            if index.get(run_id, ("error",))[0] == "error":
                index[run_id] = entries[status]

    def has(self, run_id: str) -> bool:
        """True when run ``run_id`` has a record (a result or an error)."""
        return run_id in self.index()

    def finished(self, run_id: str) -> bool:
        """True when run ``run_id`` has a result: a record that is not an error (errors are run again)."""
        return self.index().get(run_id, ("error",))[0] != "error"

    def finished_mask(self, ids: np.ndarray) -> np.ndarray:
        """:meth:`finished` of each of ``ids`` (ASCII bytes, as :attr:`.plan.PlannedRuns.ids`), as a bool array."""
        done = [i.encode("ascii") for i, (status, _) in self.index().items() if status != "error"]
        if not done:
            return np.zeros(len(ids), bool)
        return np.isin(ids, np.array(done, dtype=ids.dtype))

    def put_block(self, data: bytes) -> list[dict]:
        """Store a block file made by :func:`encode_block`; returns each run's ``id``, ``status`` and ``reason`` (an
        error's)."""
        table = pq.read_table(pa.BufferReader(data), columns=["id", "status"])
        ids, statuses = table.column("id").to_pylist(), table.column("status").to_pylist()
        name = f"{block_address(ids)}.parquet"
        self.blocks.mkdir(exist_ok=True)
        atomic_write_bytes(self.blocks / name, data)
        self._note(ids, statuses, name)
        reasons: list[str | None] = [None] * len(ids)
        errors = [i for i, status in enumerate(statuses) if status == "error"]
        if errors:  # only errors' records are decoded here: a result's is the report's to read
            records = pq.read_table(pa.BufferReader(data), columns=["record"]).column("record")
            for i in errors:
                reasons[i] = json.loads(records[i].as_py()).get("reason")
        return [{"id": i, "status": s, "reason": r} for i, s, r in zip(ids, statuses, reasons)]

    def put(self, points: list[RunPoint], *, kind: str, results: list[dict]) -> list[dict]:
        """Store the client's own records of ``points`` (errors: a design that failed, a task that failed) as one
        block."""
        records = [with_inputs(r, p, kind=kind) for p, r in zip(points, results)]
        return self.put_block(encode_block([p.id for p in points], records, campaign=self.campaign))

    def records(self) -> Iterator[tuple[str, dict]]:
        """Every stored run's record, one block file at a time (a run stored twice: the record :meth:`index` keeps)."""
        index = self.index()
        for path in self.files():
            cols = pq.read_table(path, columns=["id", "record"]).to_pydict()
            for run_id, text in zip(cols["id"], cols["record"]):
                if index[run_id][1] == path.name:
                    yield run_id, json.loads(text)

    def traces(self, ids: set[str]) -> Iterator[tuple[str, dict[str, np.ndarray]]]:
        """The stored traces of the runs ``ids`` that have a result, one block file at a time."""
        index = self.index()
        for path in self.files():
            table = pq.read_table(path, columns=["id", "status", "t", *WIDE, *(f"{k}_width" for k in WIDE)])
            for row, run_id in enumerate(table.column("id").to_pylist()):
                if run_id in ids and index[run_id] == ("done", path.name):
                    trace = _trace_of(table, row)
                    if trace is not None:
                        yield run_id, trace

    def trace_shapes(self, ids: set[str]) -> dict[tuple[int, int, int], int]:
        """How many of the runs ``ids`` that have a result have stored traces of each shape (samples, outputs,
        commands), from the ``t`` column's lengths and the widths: no output or command trace is read."""
        index, shapes = self.index(), {}
        for path in self.files():
            table = pq.read_table(path, columns=["id", "t", "y_width", "u_width"])
            names = table.column("id").to_pylist()
            lengths = pc.list_value_length(table.column("t")).to_pylist()
            widths = zip(table.column("y_width").to_pylist(), table.column("u_width").to_pylist())
            for run_id, n, (p, m) in zip(names, lengths, widths):
                if n is not None and run_id in ids and index[run_id] == ("done", path.name):
                    shapes[(n, p, m)] = shapes.get((n, p, m), 0) + 1
        return shapes

    def trace_stacks(self, ids: set[str]) -> Iterator[tuple[list[str], dict[str, np.ndarray]]]:
        """The stored traces of the runs ``ids`` that have a result, one block file at a time, stacked: for each
        block, the runs of one trace length ``N`` as ``(ids, {"t": (k, N), "y": (k, N, p), "u": ..., "r": ...})``."""
        index = self.index()
        for path in self.files():
            table = pq.read_table(path, columns=["id", "t", *WIDE, *(f"{k}_width" for k in WIDE)])
            names = table.column("id").to_pylist()
            lengths = pc.list_value_length(table.column("t")).to_pylist()
            widths = list(zip(*(table.column(f"{k}_width").to_pylist() for k in WIDE)))
            groups: dict[tuple, list[int]] = {}
            for i, run_id in enumerate(names):
                if run_id in ids and index[run_id] == ("done", path.name) and lengths[i] is not None:
                    groups.setdefault((lengths[i], *widths[i]), []).append(i)
            for (n, *shape), rows in groups.items():
                part = table.take(pa.array(rows))
                stack = {"t": pc.list_flatten(part.column("t")).to_numpy(zero_copy_only=False).reshape(len(rows), n)}
                for k, width in zip(WIDE, shape):
                    flat = pc.list_flatten(part.column(k)).to_numpy(zero_copy_only=False)
                    stack[k] = flat.reshape(len(rows), n, width)
                yield [names[i] for i in rows], stack

    def _row(self, run_id: str, columns: list[str]) -> tuple[pa.Table, int] | None:
        hit = self.index().get(run_id)
        if hit is None:
            return None
        table = pq.read_table(self.blocks / hit[1], columns=["id", *columns])
        return table, table.column("id").to_pylist().index(run_id)

    def record(self, run_id: str) -> dict:
        """The stored record of a run (KeyError when it has none)."""
        got = self._row(run_id, ["record"])
        if got is None:
            raise KeyError(run_id)
        return json.loads(got[0].column("record")[got[1]].as_py())

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


def with_inputs(record: dict, point: RunPoint | tuple, *, kind: str) -> dict:
    """``record`` with the run's ``inputs`` (kind, artifact sha256, scenario, seed), as stored."""
    sha, scenario, seed = (point.artifact_sha256, point.scenario, point.seed) if isinstance(point, RunPoint) else point
    return record | {"inputs": {"kind": kind, "artifact_sha256": sha, "scenario": scenario, "seed": seed}}
