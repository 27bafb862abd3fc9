"""Replay files: the samples a replay reads, the observer-based law's trace it writes, and the open-loop comparison of
two traces.

Which engine runs the samples, which trace format it writes and which one-step check proves it are the law's
(:meth:`gainlink.laws.Law.replay`, :meth:`~gainlink.laws.Law.trace_text`, :meth:`~gainlink.laws.Law.one_step`);
this module holds the file formats they share.

Input CSV: a header with ``y0..y{p-1}`` and ``r0..r{q-1}`` (a ``t`` column is allowed and copied through), and
``s0..`` for the law's external scheduling signals (a scheduled law's ``schedule.external``). Output CSV of the
observer-based law: ``t`` if given, ``u0..``, ``sat0..`` (1 where that input saturated), ``fault`` (1 where the
sample was refused as non-finite), ``xh0..`` and ``z0..`` (state after the step); a scheduled law's:
:mod:`gainlink.laws.scheduled.replay`. A fixed-point law's output starts with the line ``# numeric=q31`` (or
``q15``; ``float64`` from the ``reference`` engine): ``--compare`` refuses a trace of another format in one line (a
file without the line is read as before); a float32 law's output has no such line.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError, did_you_mean
from ..fileio import atomic_write_text, read_user_file
from ..shipping.artifact import Artifact
from .reference import Trace


@dataclass(frozen=True)
class Samples:
    """Measurements and references read from a replay CSV."""

    Y: np.ndarray  # (N, p)
    R: np.ndarray  # (N, q)
    t: np.ndarray | None
    S: np.ndarray | None = None  # (N, e): the law's external scheduling signals (None when it has none)


def read_samples(path: str | Path, artifact: Artifact, externals: Sequence[str] = ()) -> Samples:
    """Read a replay input CSV for ``artifact`` whose law takes the external signals ``externals``
    (:meth:`gainlink.laws.Law.externals`; columns ``s0..``); non-finite values are kept (the law handles them).

    Raises
    ------
    DataError
        Missing or unknown columns, non-numeric cells, ragged rows, or no rows.
    """
    path = Path(path)
    text = read_user_file(path, what="input", error=DataError)
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise DataError(f"input {path} is empty")
    header = [h.strip() for h in rows[0]]
    want_y = [f"y{i}" for i in range(artifact.p)]
    want_r = [f"r{i}" for i in range(artifact.q)]
    want_s = [f"s{i}" for i in range(len(externals))]
    missing = [c for c in want_y + want_r + want_s if c not in header]
    if missing:
        raise DataError(
            f"input {path} lacks column(s) {', '.join(missing)} "
            f"(artifact {artifact.name} has p={artifact.p}, q={artifact.q})"
        )
    unknown = [c for c in header if c not in set(want_y + want_r + want_s + ["t"])]
    if unknown:
        known = [*want_y, *want_r, *want_s]
        raise DataError(
            f"input {path} has unknown column {unknown[0]!r}{did_you_mean(unknown[0], [*known, 't'])}"
            f" (expected t, {', '.join(known)})"
        )
    if len(set(header)) != len(header):
        raise DataError(f"input {path} repeats a column name")
    body = rows[1:]
    if not body:
        raise DataError(f"input {path} has a header but no samples")
    data = np.empty((len(body), len(header)))
    for k, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise DataError(f"input {path} line {k} has {len(row)} fields, expected {len(header)}")
        for j, cell in enumerate(row):
            try:
                data[k - 2, j] = float(cell)
            except ValueError:
                raise DataError(f"input {path} line {k}, column {header[j]}: {cell!r} is not a number") from None
    col = {h: j for j, h in enumerate(header)}
    Y = data[:, [col[c] for c in want_y]]
    R = data[:, [col[c] for c in want_r]] if want_r else np.zeros((len(body), 0))
    t = data[:, col["t"]] if "t" in col else None
    S = data[:, [col[c] for c in want_s]] if want_s else None
    return Samples(Y=Y, R=R, t=t, S=S)


def format_trace(trace: Trace, t: np.ndarray | None = None, *, numeric: str | None = None) -> str:
    """The output CSV text for a trace (round-trip float formatting), after a ``# numeric=...`` line when
    ``numeric`` is given."""
    N, m = trace.u.shape
    n, q = trace.xh.shape[1], trace.z.shape[1]
    header = (["t"] if t is not None else []) + [f"u{i}" for i in range(m)] + [f"sat{i}" for i in range(m)]
    header += ["fault"] + [f"xh{i}" for i in range(n)] + [f"z{i}" for i in range(q)]
    out = io.StringIO()
    if numeric is not None:
        out.write(f"# numeric={numeric}\n")
    out.write(",".join(header) + "\n")
    for k in range(N):
        cells = ([_num(t[k])] if t is not None else []) + [_num(v) for v in trace.u[k]]
        cells += [str(int(s)) for s in trace.saturated[k]] + [str(int(trace.fault[k]))]
        cells += [_num(v) for v in trace.xh[k]] + [_num(v) for v in trace.z[k]]
        out.write(",".join(cells) + "\n")
    return out.getvalue()


def _num(v: float) -> str:
    v = float(v)
    return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))


def write_output(path: str | Path, text: str) -> None:
    """Write a replay's output CSV ``text`` atomically (a folder or a missing parent folder is one line)."""
    out = Path(path)
    if out.is_dir():
        raise DataError(f"output {out} is a directory")
    if not out.parent.exists():
        raise DataError(f"output folder {out.parent} does not exist")
    atomic_write_text(out, text)


@dataclass(frozen=True)
class Comparison:
    """How far one replay output is from another, open loop (information; the law's one-step check is the verdict)."""

    steps: int
    max_abs_u: float
    max_rel_u: float  # against each input's limit span u_max - u_min
    sat_mismatches: int  # steps in which any input's saturation flag differs (at most ``steps``)
    fault_mismatches: int
    sat_mismatches_per_input: tuple[int, ...] = ()  # steps in which input i's flag differs


def read_trace(path: str | Path, artifact: Artifact, *, numeric: str = "float32") -> Trace:
    """Read a replay output CSV of the observer-based law (``u``, ``sat``, ``fault``, ``xh``, ``z`` columns) of
    ``artifact``, whose law's traces are ``numeric``, back into a :class:`Trace`.

    Raises
    ------
    DataError
        The file is not a replay output for this artifact's dimensions, or it names another numeric format.
    """
    path = Path(path)
    text = _same_numeric(path, read_user_file(path, what="comparison file", error=DataError), artifact, numeric)
    rows = list(csv.DictReader(io.StringIO(text)))
    a = artifact
    try:

        def cols(prefix: str, count: int, kind=float) -> np.ndarray:
            return np.array([[kind(r[f"{prefix}{i}"]) for i in range(count)] for r in rows]).reshape(len(rows), count)

        return Trace(
            u=cols("u", a.m),
            saturated=cols("sat", a.m, int).astype(bool),
            xh=cols("xh", a.n),
            z=cols("z", a.q),
            fault=np.array([int(r["fault"]) for r in rows], dtype=bool),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(
            f"comparison file {path} is not a replay output of artifact {a.name} (bad or missing {exc})"
        ) from None


def _same_numeric(path: Path, text: str, artifact: Artifact, own: str) -> str:
    """``text`` without its ``# key=value`` lines, refused when their ``numeric`` is not ``own``, the artifact's
    format (a trace without the line is taken as before: the one-step check is its verdict)."""
    lines = text.splitlines(keepends=True)
    head = 0
    while head < len(lines) and lines[head].startswith("#"):
        head += 1
    meta = dict(ln[1:].strip().partition("=")[::2] for ln in lines[:head])
    recorded = meta.get("numeric")
    if recorded is not None and recorded.strip() != own:
        raise DataError(
            f"comparison file {path} is a trace of a {recorded.strip()} law and artifact {artifact.name} is a "
            f"{own} design: compare traces of the same numeric format"
        )
    return "".join(lines[head:])


def compare_traces(artifact: Artifact, trace: Trace, other: Trace) -> Comparison:
    """Open-loop difference of two replays of the same input (commands relative to the limit span).

    Information only: for an unstable compensator two correct implementations drift apart like
    ``|z|^k`` (see :mod:`gainlink.synthesis.compensator`); the law's one-step check
    (:meth:`gainlink.laws.Law.one_step`) is the verdict.
    """
    N = trace.u.shape[0]
    if other.u.shape[0] != N:
        raise DataError(f"comparison has {other.u.shape[0]} samples, this replay {N}")
    diff = np.abs(trace.u - other.u)
    span = artifact.u_max - artifact.u_min
    return Comparison(
        steps=N,
        max_abs_u=float(diff.max(initial=0.0)),
        max_rel_u=float((diff / span).max(initial=0.0)),
        sat_mismatches=int(np.count_nonzero((trace.saturated != other.saturated).any(axis=1))),
        fault_mismatches=int(np.sum(trace.fault != other.fault)),
        sat_mismatches_per_input=tuple(int(v) for v in (trace.saturated != other.saturated).sum(axis=0)),
    )
