"""The layout of a campaign's block file, what the worker that writes a block and the store that reads it agree on:
its columns (:data:`SCHEMA`, then the typed columns of :func:`.block_columns.row_columns`), the layout's version
(:data:`LAYOUT`), the keys a run's record and row hold, a run's traces as stored (:func:`encode_trace`) and the file's
name (:func:`block_address`)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable

import numpy as np
import pyarrow as pa
from gainlink.version import __version__

# the metrics of a tracked output and the measures ``campaign.csv`` has a cell of, in its columns' order
METRIC_CELLS = ("iae", "overshoot_pct", "settling_time_s")
MEASURE_CELLS = (
    "stable",
    "longest_saturation_s",
    "twin_output_deviation",
    "twin_command_deviation",
    "model_mismatch",
    "model_iae_ratio",
)
TRACE_FIELDS = ("t", "y", "u", "r")
WIDE = ("y", "u", "r")
SCHEMA = pa.schema(
    [
        ("id", pa.string()),
        ("status", pa.string()),
        ("record", pa.string()),
        ("record_form", pa.dictionary(pa.int32(), pa.string())),
        ("record_slots", pa.string()),
        ("record_numbers", pa.large_binary()),
        ("row", pa.string()),
        ("metrics", pa.string()),
        ("metrics_form", pa.dictionary(pa.int32(), pa.string())),
        ("metrics_slots", pa.string()),
        ("metrics_numbers", pa.large_binary()),
        ("t", pa.large_binary()),
        *((k, pa.large_binary()) for k in WIDE),
        *((f"{k}_width", pa.int32()) for k in WIDE),
    ]
)
META_VERSION, META_CAMPAIGN, META_LAYOUT = b"gainlink.version", b"gainlink.campaign", b"gainlink.block_layout"
LAYOUT = "8"  # 2: the record split into ``record`` and ``row``; 3: the row's verdict inputs as typed columns too;
# 4: each trace a run's float32 bytes (not a list of floats: Parquet's levels per value, and numpy's per run to read);
# 5: a row's typed values (complete, run_reason, measures, worker) not again in JSON: its text made from the columns;
# 6: one row group a block (5: a row group a TRACE_BATCH of runs); 7: a run's metrics as its form's template and its
# values (``metrics_form``, ``metrics_slots``, ``metrics_numbers``), their text made when read
# (:func:`.block_texts.metric_texts`); 8: a run's record the same way (``record_form``, ``record_slots``,
# ``record_numbers``; ``record`` only for a record json writes alone: :func:`.block_texts.record_texts`)
ROW_KEYS = ("complete", "measures", "metrics", "worker")  # what a report row takes from a record, as it is
# bit k of ``row_keys``: the row has ROW_BITS[k]; its measures have the twin's, the model twin's, growth ratios
ROW_BITS = ("complete", "run_reason", "worker", "measures", "metrics", "twin", "model", "growth")
TWIN_KEYS = ("twin_command_deviation", "twin_output_deviation")
MODEL_KEYS = ("model_iae_ratio", "model_mismatch", "model_warning")
MEASURE_KEYS = ("growth_ratio", "longest_saturation_s", "output_max", "output_min", "stable", "unstable_reason")
WORKER_KEYS = ("cpu_s", "host", "pid", "start", "stop")  # and ``block`` in a block's runs
MEASURES = pa.struct(
    [
        ("stable", pa.bool_()),
        ("unstable_reason", pa.string()),
        *((k, pa.float64()) for k in MEASURE_CELLS if k != "stable"),
        ("model_warning", pa.bool_()),
    ]
)
TRACKED = pa.struct([(k, pa.float64()) for k in METRIC_CELLS])
WORKER = pa.struct(
    [("host", pa.string()), ("pid", pa.int64()), ("start", pa.float64()), ("stop", pa.float64()),
     ("cpu_s", pa.float64()), ("block", pa.int64())]
)  # fmt: skip
NAMED = {"output_min": pa.float64(), "output_max": pa.float64(), "tracked": TRACKED, "outputs_final": pa.float64(),
         "growth_ratio": pa.float64()}  # fmt: skip
ROW_COLUMNS = ("row_keys", "names", "complete", "run_reason", "measures", "worker", *NAMED)
OF_MEASURES = ("output_min", "output_max", "growth_ratio")  # the NAMED structs a row's measures hold, the rest metrics'

#: The measures a run's row holds as floats (the rest: ``stable``, ``unstable_reason``, ``model_warning``, the named).
FLOAT_MEASURES = ("longest_saturation_s", "twin_command_deviation", "twin_output_deviation", "model_iae_ratio",
                   "model_mismatch")  # fmt: skip


def encode_trace(t: np.ndarray, y: np.ndarray, u: np.ndarray, r: np.ndarray) -> dict[str, np.ndarray]:
    """A run's traces as a block file stores them: float32 ``t`` (N,) and ``y`` (N x p outputs), ``u`` (N x m
    commands), ``r`` (N x q references), each contiguous.

    How a worker's record carries its traces to the block's table (:func:`.block_file.encode_block`): as arrays, not
    bytes to decode again.
    """
    out = {"t": np.ascontiguousarray(t, np.float32).reshape(-1)}
    for k, v in (("y", y), ("u", u), ("r", r)):
        out[k] = np.ascontiguousarray(v, np.float32).reshape(out["t"].size, -1)
    return out


def block_address(run_ids: Iterable[str]) -> str:
    """The content address of a block (hex, 24 characters): the sha256 of gainlink's version and its runs' ids."""
    body = "\n".join([__version__, *run_ids])
    return hashlib.sha256(body.encode("ascii")).hexdigest()[:24]


def block_file_name(run_ids: list[str]) -> str:
    """The name of the block file of runs ``run_ids`` (in its order): its :func:`block_address`."""
    return f"{block_address(run_ids)}.parquet"


#: The block file's columns whose values repeat from run to run (dictionary-encoded in the Parquet file).
REPEATED = ["status", "names", "run_reason", "record_form", "metrics_form"]
#: The block file's columns of JSON texts, compressed with zstd (every other leaf with LZ4:
#: :func:`.block_file._block_file`).
TEXTS = ("id", "record", "record_slots", "row", "metrics", "metrics_slots")
#: The columns that hold a run's metrics (:func:`.block_columns.metric_columns`, :func:`.block_texts.metric_texts`).
METRIC_COLUMNS = ("metrics", "metrics_form", "metrics_slots", "metrics_numbers")
#: The columns that hold a run's record (its id, inputs, link, status, an error's reason: :func:`.block_file._split`;
#: :func:`.block_columns.json_columns`, :func:`.block_texts.record_texts`).
RECORD_COLUMNS = ("record", "record_form", "record_slots", "record_numbers")
SLOT = "\x00"  # between a run's text slots: a JSON text holds no NUL (json writes it \u0000)
