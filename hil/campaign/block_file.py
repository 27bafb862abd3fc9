"""A block file made: the Parquet file of a block's runs (:data:`.block_layout.SCHEMA`, then the typed columns of
:mod:`.block_columns`), from the runs' records (:func:`encode_block`: the per-run path's, and the client's errors) or
from a block's lists (:func:`encode_runs`: the lockstep path's, no record dict a run), the same table either way; and
written into the campaign folder by the worker that can see it (:func:`write_block`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from gainlink.fileio import atomic_write_bytes
from gainlink.version import __version__

from .block_columns import (
    NONE,
    BlockRuns,
    blobs,
    finite_rows,
    given_columns,
    given_row,
    json_columns,
    metric_columns,
    metric_named,
    row_columns,
    row_of,
    stacked_blobs,
    tree_columns,
    tree_metric_columns,
    tree_named,
    typed_columns,
)
from .block_layout import (
    LAYOUT,
    META_CAMPAIGN,
    META_LAYOUT,
    META_VERSION,
    OF_MEASURES,
    REPEATED,
    ROW_KEYS,
    SCHEMA,
    TEXTS,
    WIDE,
    block_file_name,
)
from .jsontext import (
    compact_json,
)
from .plan import RunPoint


def encode_block(ids: list[str], records: list[dict], *, campaign: str) -> pa.Buffer:
    """The Parquet file of a block (an Arrow buffer, bytes-like): one row per run (``records[i]`` is run ``ids[i]``'s,
    its traces as :func:`.block_layout.encode_trace` arrays under ``trace``). Made on the worker, which writes it into
    the campaign folder when it can see the folder (:func:`write_block`), else returns its bytes for the client to
    write."""
    parts = [_split(run_id, record) for run_id, record in zip(ids, records)]
    rows = [row for _, row in parts]
    typed = row_columns(rows)
    names = {key: [f.name for f in typed[key].type] if key in typed else [] for key in OF_MEASURES}
    given = (finite_rows(typed, len(rows)) & np.array([given_row(row, names) for row in rows], bool)).tolist()
    texts = {
        "id": pa.array(ids, pa.string()),
        "status": pa.array([record["status"] for record in records], pa.string()),
        **json_columns([rest for rest, _ in parts], "record"),
        # JSON only for what the typed columns do not hold: a row's metrics, or a whole row they cannot give exactly
        "row": pa.array([None if ok else compact_json(row) for row, ok in zip(rows, given)], pa.string()),
        **metric_columns([row.get("metrics") if ok and "metrics" in row else NONE for row, ok in zip(rows, given)]),
    }
    return _block_file(texts, [record.get("trace") for record in records], typed, campaign=campaign)


def encode_runs(ids: list[str], runs: BlockRuns, *, campaign: str) -> pa.Buffer:
    """The Parquet file of a block of finished runs given as lists (``runs``; run ``ids[i]`` is entry ``i``): the
    file :func:`encode_block` makes of the runs' records, made a column at a time."""
    n = len(ids)
    of_metrics = tree_named(runs.metric_trees, n) if runs.metrics is None else None
    if of_metrics is None:
        runs = replace(runs, metrics=_metrics_of(runs))
        of_metrics = metric_named(runs.metrics)
    typed = typed_columns([np.ones(n, bool)] * 5, runs.complete, runs.reason, runs.measures, of_metrics, runs.worker)
    names = {key: [f.name for f in typed[key].type] if key in typed else [] for key in OF_MEASURES}
    given = finite_rows(typed, n) & given_columns(runs, names)
    if runs.metrics is None and not given.all():  # a row the typed columns cannot give is stored whole
        runs = replace(runs, metrics=_metrics_of(runs))
    texts = {
        "id": pa.array(ids, pa.string()),
        "status": pa.array(["done"] * n, pa.string()),
        **_record_columns(ids, runs),
        "row": pa.array(
            [None if ok else compact_json(row_of(runs, i)) for i, ok in enumerate(given.tolist())], pa.string()
        ),
        **_run_metric_columns(runs, given),
    }
    return _block_file(texts, runs.traces, typed, campaign=campaign)


def _record_columns(ids: list[str], runs: BlockRuns) -> dict[str, pa.Array]:
    """The record columns (:data:`.block_layout.RECORD_COLUMNS`) of the runs: each run's id, inputs, link and status,
    as :func:`encode_block` stores the record's rest; its scenario from
    :attr:`.block_columns.BlockRuns.scenario_trees` and its artifact and seed from
    :attr:`.block_columns.BlockRuns.input_columns` when the runs have them, a grid part at a time (a part's shared
    scenario once in its form's template), else from each run's inputs."""
    if runs.scenario_trees is not None and runs.input_columns is not None:
        (shas, seeds), parts = runs.input_columns, runs.scenario_trees
    else:
        shas, scenarios, seeds = (list(col) for col in zip(*runs.inputs)) if ids else ([], [], [])
        parts = [(0, len(ids), scenarios)]
    trees = []
    for a, b, scenario in parts:
        inputs = {"artifact_sha256": shas[a:b], "kind": [runs.kind] * (b - a), "scenario": scenario, "seed": seeds[a:b]}
        record = {"id": ids[a:b], "inputs": inputs, "link": runs.link[a:b], "status": ["done"] * (b - a)}
        trees.append((list(range(a, b)), record))
    return tree_columns(trees, len(ids), "record")


def _run_metric_columns(runs: BlockRuns, given: np.ndarray) -> dict[str, pa.Array]:
    """The metrics columns of ``runs`` (those not ``given`` null: their row's text holds them), from the block's
    column trees when it has them and every run is given."""
    if runs.metric_trees is not None and given.all():
        return tree_metric_columns(runs.metric_trees, len(given))
    return metric_columns(runs.metrics if given.all() else [m if ok else NONE for m, ok in zip(runs.metrics, given)])


def _metrics_of(runs: BlockRuns) -> list[dict]:
    """Each run's metrics dict: those ``runs`` holds, or made from its column trees."""
    from ..loop.block_metrics import BlockMetrics

    if runs.metrics is not None:
        return runs.metrics
    return BlockMetrics(runs.metric_trees, len(runs.complete)).rows()  # type: ignore[arg-type]


def _block_file(
    texts: dict[str, pa.Array], traces: list | dict, typed: dict[str, pa.Array], *, campaign: str
) -> pa.Buffer:
    """The Parquet file of a block, as Arrow's buffer: the JSON and text columns ``texts``, the traces (each run's
    :func:`.block_layout.encode_trace` arrays, None for none; or every run's at once, a dict of ``t`` (runs, N) and
    ``y``, ``u``, ``r`` (runs, N, width) float32 arrays, each run's rows its own), the typed columns. Not copied into a
    ``bytes`` (the worker that writes it into the folder itself writes the buffer: a copy of ~6 MB a block, and its
    pages faulted in, saved)."""
    cols = dict(texts)
    if isinstance(traces, dict):
        for k in ("t", *WIDE):
            cols[k] = stacked_blobs(traces[k])
        for k in WIDE:
            cols[f"{k}_width"] = pa.array(np.full(traces[k].shape[0], traces[k].shape[2], np.int32))
    else:
        cols["t"] = blobs([None if tr is None else tr["t"] for tr in traces])
        for k in WIDE:
            cols[k] = blobs([None if tr is None else tr[k] for tr in traces])
            cols[f"{k}_width"] = pa.array([None if tr is None else tr[k].shape[1] for tr in traces], pa.int32())
    fixed = pa.Table.from_arrays([cols[f.name] for f in SCHEMA], schema=SCHEMA)
    table = pa.table(fixed.columns + list(typed.values()), names=fixed.column_names + list(typed))
    meta = {META_VERSION: __version__.encode(), META_CAMPAIGN: campaign.encode("utf-8"), META_LAYOUT: LAYOUT.encode()}
    table = table.replace_schema_metadata(meta)
    sink = pa.BufferOutputStream()
    # Dictionaries only for the columns that repeat: tried on every column, Arrow spent 110 of 183 ms (910 runs) on
    # the traces' and the JSON texts' values, nearly all distinct, and the file came out 19 % larger. No statistics:
    # nothing reads them (a trace's min and max bytes, a JSON text's), and they were 10 % of the write. The traces in
    # LZ4: zstd gained 5 % of the file on float bytes for 3.5x the write and 3x the read (910 runs: 48 -> 14 and
    # 25 -> 8 us a run). One row group a block: a row group a TRACE_BATCH of runs cost the write ~40 % more and the
    # report's read of its columns ~75 % more (each column chunk's pages and metadata per group); the envelopes read
    # a block's traces through a buffered stream (TRACE_BUFFER), its pages as the batches need them. zstd for the
    # JSON texts only: on the typed columns' ~35 leaves its fixed cost a leaf (~30 us) was 0.9 ms of a 1,000-run
    # block's 6.5 for a file no smaller.
    codecs = {path: "zstd" if path in TEXTS else "lz4" for path in _leaf_paths(table.schema)}
    pq.write_table(
        table,
        sink,
        compression=codecs,
        use_dictionary=REPEATED,
        write_statistics=False,
        row_group_size=max(table.num_rows, 1),
    )
    return sink.getvalue()


def _leaf_paths(schema: pa.Schema) -> list[str]:
    """The Parquet column paths of ``schema``'s leaves (a struct's fields as ``name.field``): a codec given by column
    must name each leaf, or the leaf is written uncompressed."""
    paths, todo = [], [(f.name, f.type) for f in schema]
    while todo:
        path, kind = todo.pop()
        if pa.types.is_struct(kind):
            todo += [(f"{path}.{f.name}", f.type) for f in kind]
        else:
            paths.append(path)
    return paths


def _split(run_id: str, record: dict) -> tuple[dict, dict]:
    """A record (without its trace) as its ``record`` column's part (id, inputs, link, status, an error's reason)
    and its ``row`` column's (:data:`.block_layout.ROW_KEYS`; a result's ``reason`` as ``run_reason``): the report reads
    the row's text and its typed columns (:func:`.block_columns.row_columns`), not the record."""
    rest = {k: v for k, v in record.items() if k != "trace"} | {"id": run_id}
    row = {k: rest.pop(k) for k in ROW_KEYS if k in rest}
    if record["status"] != "error" and "reason" in rest:
        row["run_reason"] = rest.pop("reason")
    return rest, row


def folder_key(folder: Path) -> tuple[int, int]:
    """What a worker compares to tell that the folder it sees at a path is the client's: its device and inode."""
    st = folder.stat()
    return st.st_dev, st.st_ino


def write_block(
    folder: str, key: tuple[int, int], ids: list[str], data: bytes | pa.Buffer, errors: list
) -> dict | None:
    """Write block file ``data`` (runs ``ids``; ``errors``: ``[row, reason]`` of its errors) into the campaign's
    ``blocks`` folder when the folder at ``folder`` is the client's (``key``: :func:`folder_key` as the client saw
    it), through a temporary name and a rename as the store writes one; ``None`` when this process cannot see it
    (another machine: the client writes it). Returns what the client keeps of the block
    (:meth:`.store.Store.took_block`): its file's name, its number of runs and ``errors``."""
    path = Path(folder)
    try:
        if folder_key(path) != tuple(key):
            return None
    except OSError:
        return None
    name = block_file_name(ids)
    atomic_write_bytes(path / name, data)
    return {"block": name, "runs": len(ids), "errors": errors}


def with_inputs(record: dict, point: RunPoint | tuple, *, kind: str) -> dict:
    """``record`` with the run's ``inputs`` (kind, artifact sha256, scenario, seed), as stored."""
    sha, scenario, seed = (point.artifact_sha256, point.scenario, point.seed) if isinstance(point, RunPoint) else point
    return record | {"inputs": {"kind": kind, "artifact_sha256": sha, "scenario": scenario, "seed": seed}}
