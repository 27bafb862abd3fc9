"""A block file's runs as text again, made from its columns when read: each run's row as compact JSON
(:func:`row_texts`, the typed columns filled into one template a form of row), its metrics' and its record's JSON
(:func:`metric_texts`, :func:`record_texts`: their form's template filled with their values) and the columns' values as
JSON and CSV cells write them (:func:`value_texts`, :func:`cell_texts`): each value made text once, a column at a
time."""

from __future__ import annotations

import json
import operator
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from .block_layout import (
    FLOAT_MEASURES,
    MODEL_KEYS,
    OF_MEASURES,
    ROW_BITS,
    SLOT,
    TWIN_KEYS,
    WORKER_KEYS,
)
from .jsontext import (
    ARROW_FLOATS,
    float_texts,
    form_texts,
)


def metric_texts(table: pa.Table) -> list[str | None]:
    """Each row's metrics as compact JSON (:func:`.jsontext.compact_json` of the run's metrics; None where the file
    holds none), from the columns :func:`.block_columns.metric_columns` made (a file of layout 6 or before: its
    ``metrics`` texts)."""
    return form_texts_of(table, "metrics")


def record_texts(table: pa.Table) -> list[str | None]:
    """Each row's record as compact JSON (its id, inputs, link, status, an error's reason), from the columns
    :func:`.block_file.encode_block` and :func:`.block_file.encode_runs` made (:data:`.block_layout.RECORD_COLUMNS`)."""
    return form_texts_of(table, "record")


def form_texts_of(table: pa.Table, name: str) -> list[str | None]:
    """Each row's JSON text of the value the columns ``name`` hold (:func:`.block_columns.json_columns`: a run of a
    form, its form's template filled with its slots; a run json wrote alone, its ``name`` text; None where neither);
    a table without ``<name>_form``: its ``name`` texts."""
    out = table.column(name).to_pylist()
    if f"{name}_form" not in table.column_names:
        return out
    form = table.column(f"{name}_form").combine_chunks()
    if form.null_count == len(form):
        return out
    codes = np.asarray(pc.fill_null(form.indices, -1).to_numpy(zero_copy_only=False))
    slots, numbers = table.column(f"{name}_slots"), table.column(f"{name}_numbers")
    for code, word in enumerate(form.dictionary.to_pylist()):
        rows = np.flatnonzero(codes == code).tolist()
        if not rows:
            continue
        kinds, template = word.split("\n", 1)
        texts = kinds.count("t")
        split = [slots[i].as_py().split(SLOT) for i in rows] if texts else []
        floats = np.frombuffer(b"".join(numbers[i].as_py() for i in rows), np.float64).reshape(len(rows), -1)
        for i, text in zip(rows, form_texts(template, kinds, [list(c) for c in zip(*split)], floats)):
            out[i] = text
    return out


_TRUTH = {True: "true", False: "false", None: "null"}


def numbers_text(arr: pa.Array, *, repeated: bool = False) -> list[str]:
    """A float64 or int64 column's values as JSON writes each (``null`` where null; a float by its ``repr``, as
    json's encoder: of a long float column, through :func:`.jsontext.float_texts`). ``repeated``: a column of a few
    distinct values (a block's worker, its runs' sample times), each made text once."""
    if repeated:
        codes = pc.dictionary_encode(arr)
        words = numbers_text(codes.dictionary) + ["null"]
        return [words[k] for k in codes.indices.fill_null(len(words) - 1).to_numpy(zero_copy_only=False).tolist()]
    values = arr.to_pylist()
    if pa.types.is_float64(arr.type) and len(arr) - arr.null_count >= ARROW_FLOATS:
        if not arr.null_count:
            return float_texts(values, arr)
        made = iter(float_texts([v for v in values if v is not None], arr.drop_null()))
        return ["null" if v is None else next(made) for v in values]
    return list(map(repr, values)) if not arr.null_count else ["null" if v is None else repr(v) for v in values]


def _strings_text(arr: pa.Array) -> list[str]:
    """A string column's values as JSON writes each, each distinct one encoded once."""
    done: dict[Any, str] = {None: "null"}
    return [done[v] if v in done else done.setdefault(v, json.dumps(v)) for v in arr.to_pylist()]


def _filled(template: str, columns: list[list[str]], rows: list[int] | None = None) -> list[str]:
    """``template`` (``%s`` a value) filled with each run's texts of ``columns`` (only runs ``rows``, when given)."""
    if rows is not None and rows != list(range(len(columns[0]) if columns else 0)):
        pick = operator.itemgetter(*rows) if len(rows) > 1 else lambda col: (col[rows[0]],)
        columns = [pick(col) for col in columns]
    if not columns:
        return [template] * (len(rows) if rows is not None else 0)
    return [template % values for values in zip(*columns)]


def _object_texts(column: pa.Array | None, rows: int) -> list[str]:
    """A struct column of float64 fields (a field per name) as each run's JSON object of them, keys sorted (``{}``
    without the column)."""
    if column is None:
        return ["{}"] * rows
    fields = sorted(zip(column.type, struct_fields(column).values()), key=lambda f: f[0].name)
    template = "{" + ",".join(_key(f.name) + "%s" for f, _ in fields) + "}"
    return _filled(template, [numbers_text(arr) for _, arr in fields])


def _key(name: str) -> str:
    """An object key as compact JSON writes it, with its colon, escaped for a ``%`` template."""
    return (json.dumps(name) + ":").replace("%", "%%")


def row_texts(table: pa.Table, texts: dict[str, list[str]] | None = None) -> list[str]:
    """Each row's JSON text, as ``json.dumps(row, sort_keys=True, separators=(",", ":"))`` writes the
    :func:`.block_file._split` ``row`` the block was made from: the ``row`` column's where the typed columns could not
    give it exactly (:func:`.block_columns.given_row`), else made from the typed columns and the ``metrics`` column's
    text: each value made text once, a column at a time (``texts``: :func:`value_texts` of ``table``, when made
    already), and the runs of one form (which keys the row and its measures have, which are null) filled into one
    template."""
    out = table.column("row").to_pylist()
    typed = np.flatnonzero(table.column("row").is_null().to_numpy(zero_copy_only=False))
    if not typed.size:
        return out
    texts = value_texts(table) if texts is None else texts
    form = table.column("row_keys").to_numpy(zero_copy_only=False).astype(np.int64)
    for k, col in enumerate(("measures", "worker")):
        form |= np.asarray(table.column(col).is_valid().to_numpy(zero_copy_only=False), np.int64) << (8 + k)
    block = table.column("worker").combine_chunks().field("block").is_valid().to_numpy(zero_copy_only=False)
    form |= np.asarray(block, np.int64) << 10
    forms = form[typed]
    for f in np.unique(forms).tolist():
        rows = typed[forms == f].tolist()
        template, names = _row_template(f)
        for i, text in zip(rows, _filled(template, [texts[name] for name in names], rows)):
            out[i] = text
    return out


def _row_template(form: int) -> tuple[str, list[str]]:
    """The JSON text of the rows of one ``form`` (bits: :data:`.block_layout.ROW_BITS`, then whether ``measures``,
    ``worker`` and ``worker.block`` are not null) as a ``%`` template and the names of the texts (:func:`value_texts`)
    it takes."""
    has = {name: bool(form >> k & 1) for k, name in enumerate((*ROW_BITS, "measures?", "worker?", "block?"))}
    parts: list[tuple[str, str | None]] = []  # (literal text, the value after it)
    if has["complete"]:
        parts.append(('"complete":', "complete"))
    if has["measures"] and not has["measures?"]:
        parts.append(('"measures":null', None))
    elif has["measures"]:
        names = ["growth_ratio" if has["growth"] else None, "longest_saturation_s"]
        names += list(MODEL_KEYS) if has["model"] else []
        names += ["output_max", "output_min", "stable"] + (list(TWIN_KEYS) if has["twin"] else []) + ["unstable_reason"]
        for k, name in enumerate(names):
            head = ('"measures":{' if k == 0 else ",") + _key(name or "growth_ratio")
            parts.append((head + ("{}" if name is None else ""), name))
        parts.append(("}", None))
    if has["metrics"]:
        parts.append(('"metrics":', "metrics"))
    if has["run_reason"]:
        parts.append(('"run_reason":', "run_reason"))
    if has["worker"] and not has["worker?"]:
        parts.append(('"worker":null', None))
    elif has["worker"]:
        names = (["block"] if has["block?"] else []) + list(WORKER_KEYS)
        for k, name in enumerate(names):
            parts.append((('"worker":{' if k == 0 else ",") + _key(name), "worker." + name))
        parts.append(("}", None))
    template, names, first = "{", [], True
    for text, name in parts:
        lead = "," if not first and text[0] == '"' else ""
        first = False
        template += lead + text + ("" if name is None else "%s")
        if name is not None:
            names.append(name)
    return template + "}", names


def cell_texts(table: pa.Table) -> dict[str, list[str]]:
    """The typed values a row's ``campaign.csv`` cells and its text share (``complete``, ``stable`` and the float
    measures), as JSON text, by name, one list a column over the block's runs."""
    measures = struct_fields(table.column("measures"))
    texts = {k: numbers_text(measures[k], repeated=k == "longest_saturation_s") for k in FLOAT_MEASURES}
    texts["stable"] = [_TRUTH[v] for v in measures["stable"].to_pylist()]
    texts["complete"] = [_TRUTH[v] for v in table.column("complete").to_pylist()]
    return texts


def value_texts(table: pa.Table, cells: dict[str, list[str]] | None = None) -> dict[str, list[str]]:
    """Each typed value a row's text holds, as JSON text, by name (``worker.pid``; a measure by its own name), one
    list a column over the block's runs (``cells``: :func:`cell_texts` of ``table``, when made already)."""
    n = table.num_rows
    measures = struct_fields(table.column("measures"))
    worker = struct_fields(table.column("worker"))
    texts = dict(cell_texts(table) if cells is None else cells)
    texts["model_warning"] = [_TRUTH[v] for v in measures["model_warning"].to_pylist()]
    texts["unstable_reason"] = _strings_text(measures["unstable_reason"])
    texts |= {key: _object_texts(table.column(key).combine_chunks() if key in table.column_names else None, n)
              for key in OF_MEASURES}  # fmt: skip
    texts |= {f"worker.{k}": numbers_text(worker[k], repeated=True) for k in ("block", "cpu_s", "pid", "start", "stop")}
    texts["worker.host"] = _strings_text(worker["host"])
    texts["run_reason"] = _strings_text(table.column("run_reason").combine_chunks())
    texts["metrics"] = metric_texts(table)
    return texts


def joined(rest: dict, row: dict) -> dict:
    """The record :func:`.block_file._split` split."""
    if "run_reason" in row:
        row = {k: v for k, v in row.items() if k != "run_reason"} | {"reason": row["run_reason"]}
    return rest | row


def struct_fields(column: pa.ChunkedArray | pa.Array) -> dict[str, pa.Array]:
    """A struct column's fields by name, null where the struct is (``StructArray.flatten``)."""
    col = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    return {f.name: arr for f, arr in zip(col.type, col.flatten())}
