"""A block's runs as the typed columns of its file (:data:`.block_layout.SCHEMA` holds the rest): a run's row
(:func:`row_columns`: what the verdicts and ``campaign.csv`` read), its metrics (:func:`metric_columns`,
:func:`tree_metric_columns`: each form's template and its values) and arrays as binary values (:func:`blobs`), made
from the runs' records or from a block's lists (:class:`BlockRuns`); with the checks that the columns give a run's row
exactly (:func:`given_row`, :func:`given_columns`, :func:`finite_rows`): a row they cannot give is stored whole as
JSON."""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import chain
from operator import itemgetter
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from .block_layout import (
    FLOAT_MEASURES,
    MEASURE_KEYS,
    MEASURES,
    MODEL_KEYS,
    NAMED,
    OF_MEASURES,
    ROW_BITS,
    SLOT,
    TRACKED,
    TWIN_KEYS,
    WORKER,
)
from .jsontext import (
    Form,
    compact_json,
    json_forms,
    tree_forms,
)


@dataclass(frozen=True)
class BlockRuns:
    """The finished runs of a block as lists, one entry a run, what a block's records would hold (``status`` done, a
    ``reason`` each, no ``row`` key missing): :func:`.block_file.encode_runs` stores them as
    :func:`.block_file.encode_block` stores their records, without a record dict a run."""

    kind: str
    inputs: list  # (artifact sha256, scenario, seed) of each run, as :func:`.block_file.with_inputs` takes them
    complete: list
    reason: list
    metrics: list | None  # each run's dict; None when its metric_trees hold them (made from those when needed)
    measures: list
    link: list
    traces: list | dict  # encode_trace's arrays, or all runs' at once (:func:`.block_file._block_file`)
    worker: list  # each run's: its block's share (host, pid, start, stop, cpu_s, block), one dict a block
    metric_trees: list | None = None  # the metrics as column trees (:func:`tree_metric_columns`), when made so
    # the scenarios of ``inputs`` as column trees, (start, stop, tree) in order (DescribedRuns.scenario_trees), and
    # with them each run's artifact sha256 and seed (MadeRuns.columns): the record texts made without a run's inputs
    scenario_trees: list | None = None
    input_columns: tuple[list, list] | None = None


def row_of(runs: BlockRuns, i: int, *, metrics: bool = True) -> dict:
    """Run ``i``'s ``row`` (:func:`.block_file._split`'s) of ``runs``; without its metrics when ``metrics`` is false
    (what :func:`given_row` checks holds none: a block's dicts are made from its trees only for a row stored whole)."""
    row = {"complete": runs.complete[i], "measures": runs.measures[i], "worker": runs.worker[i],
           "run_reason": runs.reason[i]}  # fmt: skip
    return row | {"metrics": runs.metrics[i]} if metrics else row  # type: ignore[index]


NONE = object()  # a run whose value (a row's metrics) the columns do not hold


def metric_columns(metrics: list) -> dict[str, pa.Array]:
    """The columns of the runs' metrics (:data:`.block_layout.METRIC_COLUMNS`; ``metrics[i]`` :data:`NONE`: null in
    each): :func:`json_columns` named ``metrics``."""
    return json_columns(metrics, "metrics")


def tree_metric_columns(trees: list[tuple[list[int], Any]], runs: int) -> dict[str, pa.Array]:
    """:func:`metric_columns` of ``runs`` runs whose metrics are given as column trees (``(positions, tree)``, each
    run in one: :class:`~..loop.block_metrics.BlockMetrics`), made from the trees' columns, not a dict a run."""
    return tree_columns(trees, runs, "metrics")


def json_columns(values: list, name: str) -> dict[str, pa.Array]:
    """The four columns ``name`` that hold a JSON value of each run (its metrics, its record:
    :data:`.block_layout.METRIC_COLUMNS`, :data:`.block_layout.RECORD_COLUMNS`; ``values[i]`` :data:`NONE`: null in
    each), made for the block's runs at once (:func:`.jsontext.json_forms`): a run of a structure the block's runs
    share holds its form (``<name>_form``: the structure's kinds of slots, a newline, its ``%`` template; a block's
    runs share one or a few), its text slots joined by :data:`.block_layout.SLOT` (``<name>_slots``) and its float slots
    as float64 bytes (``<name>_numbers``), no text made of a float; a run json writes alone holds its text
    (``<name>``). Read back by :func:`.block_texts.form_texts_of`."""
    held = [k for k, m in enumerate(values) if m is not NONE]
    if len(held) == len(values):
        return _form_columns(*json_forms(values), len(values), name)
    forms, whole = json_forms([values[k] for k in held])
    forms = [replace(form, rows=[held[j] for j in form.rows]) for form in forms]
    return _form_columns(forms, {held[j]: text for j, text in whole.items()}, len(values), name)


def tree_columns(trees: list[tuple[list[int], Any]], runs: int, name: str) -> dict[str, pa.Array]:
    """:func:`json_columns` of ``runs`` runs whose values are given as column trees (``(positions, tree)``, each run
    in one; a tree as :func:`.jsontext.object_texts` takes it), made from the trees' columns, not a dict a run."""
    forms: list[Form] = []
    whole: dict[int, str] = {}
    for positions, tree in trees:
        made, texts = tree_forms(tree, len(positions))
        forms += [replace(form, rows=[positions[j] for j in form.rows]) for form in made]
        whole |= {positions[j]: text for j, text in texts.items()}
    return _form_columns(forms, whole, runs, name)


def _form_columns(forms: list[Form], whole: dict[int, str], n: int, name: str) -> dict[str, pa.Array]:
    """The columns ``name`` of ``n`` runs from their forms (:class:`.jsontext.Form`, rows the runs') and the texts of
    the runs json writes alone; the forms in the order of their first run (whichever way they were found)."""
    forms = sorted(forms, key=lambda form: min(form.rows))
    if not whole and len(forms) == 1 and forms[0].rows == list(range(n)):
        return _one_form_columns(forms[0], n, name)
    texts: list[str | None] = [None] * n
    codes = np.full(n, -1, np.int32)
    slots: list[str | None] = [None] * n
    numbers: list[np.ndarray | None] = [None] * n
    for code, form in enumerate(forms):
        rows = form.rows
        codes[rows] = code
        text = [col for kind, col in zip(form.kinds, form.columns) if kind == "t"]
        for i, joined in zip(rows, map(SLOT.join, zip(*text)) if text else [""] * len(rows)):
            slots[i] = joined
        floats = [col for kind, col in zip(form.kinds, form.columns) if kind == "f"]
        values = np.array(floats, np.float64).T.copy() if floats else np.zeros((len(rows), 0))
        for i, row in zip(rows, values):
            numbers[i] = row
    for i, text in whole.items():
        texts[i] = text
    words = [form.kinds + "\n" + form.template for form in forms]
    return {
        name: pa.array(texts, pa.string()),
        f"{name}_form": pa.DictionaryArray.from_arrays(
            pa.array(codes, pa.int32(), mask=codes < 0), pa.array(words, pa.string())
        ),
        f"{name}_slots": pa.array(slots, pa.string()),
        f"{name}_numbers": blobs(numbers, np.float64),
    }


def _one_form_columns(form: Form, n: int, name: str) -> dict[str, pa.Array]:
    """:func:`_form_columns` of ``n`` runs of one form, run ``i`` its ``i``-th (the usual block): its slots joined a
    column at a time and its numbers one (runs, float slots) array, not a row at a time."""
    text = [col for kind, col in zip(form.kinds, form.columns) if kind == "t"]
    floats = [col for kind, col in zip(form.kinds, form.columns) if kind == "f"]
    numbers = np.array(floats, np.float64).T if floats else np.zeros((n, 0))
    return {
        name: pa.nulls(n, pa.string()),
        f"{name}_form": pa.DictionaryArray.from_arrays(
            pa.array(np.zeros(n, np.int32)), pa.array([form.kinds + "\n" + form.template], pa.string())
        ),
        f"{name}_slots": pa.array(list(map(SLOT.join, zip(*text))) if text else [""] * n, pa.string()),
        f"{name}_numbers": stacked_blobs(numbers, np.float64),
    }


def row_columns(rows: list[dict]) -> dict[str, pa.Array]:
    """What the verdicts and ``campaign.csv`` read of the rows ``rows`` (each a :func:`.block_file._split` ``row``), as
    typed columns beside its JSON text (which a run's row and :meth:`.store.Store.record` give as it is):

    - ``row_keys`` (uint8): bit k set when the row has :data:`.block_layout.ROW_BITS` [k] (a key holding ``None`` is not
    a key
      missing: the verdict's JSON says ``null`` for a missing one);
    - ``names`` (dictionary of strings): the run's tracked outputs and outputs (``metrics.tracked``,
      ``metrics.outputs_final``), sorted, as the JSON ``[[tracked...], [outputs...]]``: its CSV columns;
    - ``complete`` (bool), ``run_reason`` (string), ``measures`` (:data:`.block_layout.MEASURES`: the measures the
    criteria and
      the CSV read), ``worker`` (:data:`.block_layout.WORKER`); null where the row holds ``None`` or lacks it;
    - :data:`.block_layout.NAMED`: ``output_min``, ``output_max`` (the measures'), ``tracked`` and ``outputs_final``
    (the
      metrics'), each a struct with a field per name some row of the block has (a tracked output a row lacks: a
      null struct), left out when no row has one (Parquet has no struct without fields).
    """
    return typed_columns(
        [np.array([key in row for row in rows], bool) for key in ROW_BITS[:5]],
        [row.get("complete") for row in rows],
        [row.get("run_reason") for row in rows],
        [row.get("measures") for row in rows],
        metric_named([row.get("metrics") for row in rows]),
        [row.get("worker") for row in rows],
    )


def typed_columns(
    has: list[np.ndarray], complete: list, reason: list, measures: list, of_metrics: dict, worker: list | pa.Array
) -> dict[str, pa.Array]:
    """:func:`row_columns` of rows given a list a key: ``has[k]``, whether each row has :data:`.block_layout.ROW_BITS`
    [k] (the first five); a row's ``complete``, ``run_reason``, ``measures``, ``worker`` (None where it has not;
    ``worker`` a list of dicts or its column made already); the columns of their metrics (``of_metrics``:
    :func:`metric_named`)."""
    bits = np.zeros(len(complete), np.uint8)
    for k, present in enumerate(has):
        bits |= present.astype(np.uint8) << k
    held = [m if type(m) is dict else {} for m in measures]
    bits |= np.array([TWIN_KEYS[0] in m for m in held], np.uint8) << 5
    bits |= np.array([MODEL_KEYS[0] in m for m in held], np.uint8) << 6
    bits |= np.array([bool(m.get("growth_ratio")) for m in held], np.uint8) << 7
    cols: dict[str, pa.Array] = {"row_keys": pa.array(bits, pa.uint8()), "names": of_metrics["names"]}
    cols["complete"] = pa.array(complete, pa.bool_())
    cols["run_reason"] = pa.array(reason, pa.string())
    cols["measures"] = pa.array(measures, MEASURES)
    cols["worker"] = worker if isinstance(worker, pa.Array) else pa.array(worker, WORKER)
    for key, kind in NAMED.items():
        if key not in OF_MEASURES:
            if key in of_metrics:
                cols[key] = of_metrics[key]
            continue
        held = [(m or {}).get(key) for m in measures]
        names = sorted(set().union(*(d for d in held if d)))
        if names:
            cols[key] = pa.array(held, pa.struct([(n, kind) for n in names]))
    return cols


def metric_named(metrics: list) -> dict[str, pa.Array]:
    """The typed columns of the runs' metrics (each a dict, or None): ``names`` (:func:`_names`) and the
    :data:`.block_layout.NAMED` structs the metrics hold (``tracked``, ``outputs_final``), each left out when no run has
    a name."""
    metrics = [m or {} for m in metrics]
    cols = {"names": _names(metrics)}
    for key in _OF_METRICS:
        held = [m.get(key) for m in metrics]
        names = sorted(set().union(*(d for d in held if d)))
        if names:
            cols[key] = pa.array(held, pa.struct([(n, NAMED[key]) for n in names]))
    return cols


_OF_METRICS = tuple(key for key in NAMED if key not in OF_MEASURES)  # the NAMED structs a run's metrics hold


def tree_named(trees: list | None, n: int) -> dict[str, pa.Array] | None:
    """:func:`metric_named` of ``n`` runs from their metrics' column trees (:class:`~..loop.block_metrics.
    BlockMetrics`' ``trees``) when one tree of dicts holds them all in order, each name's figures a column (the
    usual block); else None (the runs' dicts are made)."""
    if not trees or len(trees) != 1 or trees[0][0] != list(range(n)) or not isinstance(trees[0][1], dict):
        return None
    tree = trees[0][1]
    tracked, final = tree.get("tracked", {}), tree.get("outputs_final", {})
    if not isinstance(tracked, dict) or not isinstance(final, dict):
        return None
    cells = [t.get(c) if isinstance(t, dict) else None for t in tracked.values() for c in TRACKED.names]
    if not all(isinstance(col, list) for col in [*cells, *final.values()]):
        return None
    words = [compact_json([sorted(tracked), sorted(final)])]
    cols = {"names": pa.DictionaryArray.from_arrays(pa.array(np.zeros(n, np.int32)), pa.array(words, pa.string()))}
    if tracked:
        cols["tracked"] = pa.StructArray.from_arrays(
            [_struct_of({c: tracked[name][c] for c in TRACKED.names}, TRACKED) for name in sorted(tracked)],
            fields=[pa.field(name, TRACKED) for name in sorted(tracked)],
        )
    if final:
        kind = NAMED["outputs_final"]
        cols["outputs_final"] = _struct_of(final, pa.struct([(name, kind) for name in sorted(final)]))
    return cols


def _struct_of(columns: dict[str, list], kind: pa.StructType) -> pa.StructArray:
    """The struct array of type ``kind`` whose field ``f`` holds ``columns[f]`` (each field a column of its type)."""
    return pa.StructArray.from_arrays([pa.array(columns[f.name], f.type) for f in kind], fields=list(kind))


_MEASURE_SETS = {
    frozenset(MEASURE_KEYS + twin + model) for twin in ((), TWIN_KEYS) for model in ((), MODEL_KEYS)
}  # the key sets a run's measures have (:func:`.criteria.measure`): with or without each twin's


_NUMBERS = frozenset({float, type(None)})  # what a float64 column gives back as JSON wrote it (not an int, not numpy's)


def given_row(row: dict, names: dict[str, list[str]]) -> bool:
    """Whether the typed columns give row ``row`` (a :func:`.block_file._split` ``row``) exactly, so that
    :func:`.block_texts.row_texts` makes its JSON text from them and its metrics' text: each value of the types its
    column holds, its measures one of the key sets :func:`.criteria.measure` makes, with the block's names (``names``:
    the :data:`.block_layout.OF_MEASURES` structs' fields) in ``output_min`` and ``output_max`` and in ``growth_ratio``
    or none. (Its floats' finiteness is checked over the columns, :func:`finite_rows`.)"""
    complete, reason, worker = row.get("complete"), row.get("run_reason"), row.get("worker")
    if not (complete is None or type(complete) is bool) or not (reason is None or type(reason) is str):
        return False
    if worker is not None and not _given_worker(worker):
        return False
    m = row.get("measures")
    if m is None:
        return True
    if type(m) is not dict or frozenset(m) not in _MEASURE_SETS:
        return False
    if not all(m.get(k) is None or type(m[k]) is bool for k in ("stable", "model_warning")):
        return False
    if not (m["unstable_reason"] is None or type(m["unstable_reason"]) is str):
        return False
    if not {type(m[k]) for k in FLOAT_MEASURES if k in m} <= _NUMBERS:
        return False
    for key in OF_MEASURES:
        held = m[key]
        if type(held) is not dict or not set(map(type, held.values())) <= _NUMBERS:
            return False
        if sorted(held) != names[key] and (held or key != "growth_ratio"):  # growth ratios: every name's or none
            return False
    return True


def given_columns(runs: BlockRuns, names: dict[str, list[str]]) -> np.ndarray:
    """:func:`given_row` of each run of ``runs``, checked a column at a time when the runs' values are of one form (the
    usual block: every measures dict of one key set, the block's names in each), else run by run."""
    n = len(runs.complete)
    if n and _one_form(runs, names):
        return np.ones(n, bool)
    return np.array([given_row(row_of(runs, i, metrics=False), names) for i in range(n)], bool)


def _one_form(runs: BlockRuns, names: dict[str, list[str]]) -> bool:
    """Whether every run of ``runs`` is given (:func:`given_row`), by checks over its columns: False may be wrong."""
    if not set(map(type, runs.complete)) <= {bool, type(None)} or not set(map(type, runs.reason)) <= {str, type(None)}:
        return False
    shares = {id(w): w for w in runs.worker}.values()  # a block's runs share one
    if not all(map(_given_worker, shares)) or set(map(type, runs.measures)) != {dict}:
        return False
    keys = sorted(runs.measures[0])
    if frozenset(keys) not in _MEASURE_SETS or set(map(len, runs.measures)) != {len(keys)}:
        return False
    try:
        columns = dict(zip(keys, zip(*map(itemgetter(*keys), runs.measures))))
    except KeyError:
        return False
    kinds = {key: set(map(type, col)) for key, col in columns.items()}
    if not all(kinds[k] <= {bool, type(None)} for k in ("stable", "model_warning") if k in kinds):
        return False
    if not kinds["unstable_reason"] <= {str, type(None)} or not all(
        kinds[k] <= _NUMBERS for k in FLOAT_MEASURES if k in kinds
    ):
        return False
    return all(_named_given(columns[key], names[key], empty=key == "growth_ratio") for key in OF_MEASURES)


def _named_given(held: tuple, names: list[str], *, empty: bool) -> bool:
    """Whether each of ``held`` (a measure's dicts by name) is a dict of floats or None with keys ``names`` (or no
    key, when ``empty``)."""
    if set(map(type, held)) != {dict}:
        return False
    sizes = set(map(len, held))
    if sizes != {len(names)} and not (empty and sizes <= {0, len(names)}):
        return False
    full = [d for d in held if d] if 0 in sizes else list(held)
    if not names:
        return not full
    try:
        values = list(map(itemgetter(*names), full))
    except KeyError:
        return False
    values = values if len(names) > 1 else [(v,) for v in values]
    return set(map(type, chain.from_iterable(values))) <= _NUMBERS


def _given_worker(worker: Any) -> bool:
    """Whether a row's ``worker`` is the dict a worker records (:data:`.block_layout.WORKER_KEYS`, and ``block`` in a
    block)."""
    if type(worker) is not dict or len(worker) != (5 if "block" not in worker else 6):
        return False
    if "block" in worker and type(worker["block"]) is not int:
        return False
    host, pid = worker.get("host"), worker.get("pid")
    if type(host) is not str or type(pid) is not int:
        return False
    return all(type(worker.get(k)) is float for k in ("start", "stop", "cpu_s"))


def finite_rows(typed: dict[str, pa.Array], rows: int) -> np.ndarray:
    """Which rows have no infinite or NaN value in the floats of the typed columns a row's text is made from (JSON
    refuses them: such a row is kept whole, and its JSON raises as it did)."""
    ok = np.ones(rows, bool)
    todo = [typed[k] for k in ("measures", "worker", *OF_MEASURES) if k in typed]
    for col in todo:
        for field, arr in zip(col.type, col.flatten()):
            if pa.types.is_floating(field.type) and arr.null_count < len(arr):
                ok &= np.asarray(pc.fill_null(pc.is_finite(arr), True).to_numpy(zero_copy_only=False), bool)
    return ok


def _names(metrics: list[dict]) -> pa.DictionaryArray:
    """Each run's ``[[tracked...], [outputs...]]`` (sorted), dictionary-encoded: a block's runs share one or two."""
    texts: dict[tuple, int] = {}
    codes = []
    for m in metrics:
        key = (tuple(sorted(m.get("tracked", ()))), tuple(sorted(m.get("outputs_final", ()))))
        codes.append(texts.setdefault(key, len(texts)))
    words = [compact_json([list(t), list(o)]) for t, o in texts]
    return pa.DictionaryArray.from_arrays(pa.array(codes, pa.int32()), pa.array(words, pa.string()))


def blobs(rows: list[np.ndarray | None], dtype: type = np.float32) -> pa.LargeBinaryArray:
    """Arrays of ``dtype`` (``None``: no value) as one Arrow binary array, each row its array's bytes in C order: one
    concatenation and its offsets, not an Arrow value a row. Parquet writes a binary value as one length and its bytes
    (a list of floats: a repetition and a definition level per float, 2.3x the CPU of the block file's write)."""
    valid = np.array([r is not None for r in rows], bool)
    present = [r for r in rows if r is not None]
    sizes = np.zeros(len(rows), np.int64)
    sizes[valid] = [r.size for r in present]
    sizes *= np.dtype(dtype).itemsize
    offsets = np.concatenate(([0], np.cumsum(sizes)))
    # axis None: each array flattened in C order into the one copy (not a copy and a view a row: ~0.8 us a run)
    data = np.concatenate(present, axis=None, dtype=dtype, casting="same_kind") if present else np.zeros(0, dtype)
    bits = pa.py_buffer(np.packbits(valid, bitorder="little"))
    buffers = [bits, pa.py_buffer(offsets), pa.py_buffer(data)]
    return pa.Array.from_buffers(pa.large_binary(), len(rows), buffers, null_count=int((~valid).sum()))


def stacked_blobs(A: np.ndarray, dtype: type = np.float32) -> pa.LargeBinaryArray:
    """:func:`blobs` of the rows of ``A`` (runs, ...) as ``dtype``, none missing: its bytes as they lie when C-ordered
    (not copied when so already: a block's outputs and commands, ~6 MB a 1,000-run block), each row one value."""
    data = np.ascontiguousarray(A, dtype).reshape(-1)
    size = data.size // max(A.shape[0], 1) * data.itemsize
    offsets = np.arange(A.shape[0] + 1, dtype=np.int64) * size
    return pa.Array.from_buffers(pa.large_binary(), A.shape[0], [None, pa.py_buffer(offsets), pa.py_buffer(data)])
