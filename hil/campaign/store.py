"""A campaign folder: inputs (artifacts and FMUs by sha256, the plan) and one result file per run id.

::

    DIR/plan.json               every run: id, index, axis values, seed, artifact sha256, scenario
    DIR/artifacts/<sha256>.json DIR/fmus/<sha256>.fmu      what travelled to the workers
    DIR/runs/<id>.json          one finished run (inputs, status, metrics, measures, worker)
    DIR/runs/<id>.npy           its downsampled traces: ``np.load(path)["y"]`` (fields t, y, u, r; float32)
    DIR/campaign.json campaign.csv summary.txt *.png           the merged report (see report.py)

Every file is written to a temporary name and renamed; a run's ``.json`` is written after its ``.npy``,
so a run counts as done exactly when its ``.json`` exists, and a campaign killed at any point resumes
by running the ids without one, and those whose record is an error (an error is not a result: run the
campaign again once its cause is fixed).
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.fileio import atomic_write_bytes, atomic_write_text, prepare_output_dir
from gainlink.version import __version__

from .config import CampaignError
from .plan import CampaignPlan, RunPoint

TRACE_FIELDS = ("t", "y", "u", "r")


def encode_trace(t: np.ndarray, y: np.ndarray, u: np.ndarray, r: np.ndarray) -> bytes:
    """A run's traces as the bytes of one ``.npy`` file: a structured float32 array of ``N`` samples with
    fields ``t`` (time), ``y`` (N x p outputs), ``u`` (N x m commands), ``r`` (N x q references).

    The worker encodes (one ``np.save`` into memory, no compression: ~10x cheaper to write and to read
    than a compressed ``.npz``), so the client only writes bytes: it stores every run of the campaign.
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


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, indent=1, allow_nan=False) + "\n"


def _compact_json(obj: Any) -> str:
    # No indent: json's C encoder (indent falls back to the Python one, 10x slower: one file per run).
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False) + "\n"


def refuse_foreign(out: str | Path, plan_doc: dict) -> None:
    """Refuse, in one line and before anything is written, to resume into ``out`` when its ``plan.json`` is another
    campaign's (another name) or another gainlink version's (its runs would be ignored, not resumed)."""
    path = Path(out) / "plan.json"
    if not path.is_file():
        return
    try:
        old = json.loads(path.read_text("utf-8"))["campaign"]
        name, version = old["name"], old.get("gainlink")
    except (OSError, ValueError, KeyError, TypeError):
        raise CampaignError(
            f"campaign: {path} is not a campaign plan this gainlink can read; give another --out"
        ) from None
    new = plan_doc["campaign"]["name"]
    if name != new:
        raise CampaignError(f"campaign: {out} holds campaign {name!r}, not {new!r}: give another --out")
    if version != __version__:
        raise CampaignError(
            f"campaign: {out} was written by gainlink {version or 'older than 0.1.0'}, this is {__version__}: "
            "its runs would not be reused; give another --out"
        )


class Store:
    """The campaign folder ``out`` (created on demand)."""

    def __init__(self, out: str | Path) -> None:
        self.out = prepare_output_dir(out)
        self.runs = self.out / "runs"
        self.runs.mkdir(exist_ok=True)

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

    def has(self, run_id: str) -> bool:
        """True when run ``run_id`` has a record (a result or an error)."""
        return (self.runs / f"{run_id}.json").is_file()

    def finished(self, run_id: str) -> bool:
        """True when run ``run_id`` has a result: a record that is not an error (errors are run again)."""
        try:
            return self.record(run_id).get("status") != "error"
        except (OSError, ValueError):
            return False

    def put(self, point: RunPoint, *, kind: str, result: dict) -> dict:
        """Record a finished (or failed) run; returns the record written."""
        trace = result.get("trace")  # encode_trace's bytes, made on the worker
        if trace is not None:
            atomic_write_bytes(self.runs / f"{point.id}.npy", trace)
        record = {k: v for k, v in result.items() if k != "trace"}
        record.update(
            {
                "id": point.id,
                "inputs": {
                    "kind": kind,
                    "artifact_sha256": point.artifact_sha256,
                    "scenario": point.scenario,
                    "seed": point.seed,
                },
            }
        )
        atomic_write_text(self.runs / f"{point.id}.json", _compact_json(record))
        return record

    def record(self, run_id: str) -> dict:
        """The stored record of a run."""
        return json.loads((self.runs / f"{run_id}.json").read_text("utf-8"))

    def trace(self, run_id: str) -> dict[str, np.ndarray] | None:
        """The stored downsampled traces of a run, if any."""
        path = self.runs / f"{run_id}.npy"
        if not path.is_file():
            return self._npz_trace(run_id)
        with open(path, "rb") as fh:
            return decode_trace(fh)

    def _npz_trace(self, run_id: str) -> dict[str, np.ndarray] | None:
        """The traces of a run stored by an earlier gainlink, as a compressed ``.npz`` of t, y, u, r: a folder
        resumed across the change to ``.npy`` keeps every run in its envelopes."""
        path = self.runs / f"{run_id}.npz"
        if not path.is_file():
            return None
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in TRACE_FIELDS}

    def artifact_bytes(self, sha: str) -> bytes:
        """An artifact that travelled with the campaign."""
        return (self.out / "artifacts" / f"{sha}.json").read_bytes()

    def blobs(self) -> dict[str, bytes]:
        """Every FMU that travelled with the campaign."""
        folder = self.out / "fmus"
        return {p.stem: p.read_bytes() for p in folder.glob("*.fmu")} if folder.is_dir() else {}
