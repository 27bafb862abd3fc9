"""Replay files and the one-step check of the scheduled law (schema-2 artifacts).

Input CSV: as for the unscheduled law (``t``, ``y0..``, ``r0..``), plus ``s0..s{e-1}`` when the artifact is
scheduled on external signals (``schedule.external``, in order). Output CSV: a first line ``# numeric=float64`` (the
reference engine's trace) or ``# numeric=float32`` (the C's, or its model's), then ``t`` if given, ``u0..``,
``sat0..``, ``fault``, ``sigma`` (the sigma the step used), ``sflags`` (1 held, 2 clipped, 4 rate-limited), then the
state after the step: ``d0..`` (the estimate's increment), ``up0..`` (the previous command), ``yp0..``, ``ep0..``,
``sh`` (the held sigma), ``sf`` (the filter's state), ``started``. A file without the first line (written before it
existed) is read as a float64 trace.

The one-step check resynchronises a law on an engine's state before each step, as for the unscheduled law
(:mod:`gainlink.proof.onestep`). A float64 trace (the reference engine) is checked against the float64 law within
float64's bound: ``REL`` times each quantity's magnitude in that step. A trace of the C (engines ``native`` and
``qemu``, ``firmware/src/gl_sched.c``) is checked against the C's float32 arithmetic,
:class:`~gainlink.laws.scheduled.model.ScheduledFloat32Loop`, bit for bit (``float32=True``), and against the
float64 law within a float32 bound, as the unscheduled check does (:mod:`gainlink.laws.scheduled.onestep`).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ...errors import DataError
from ...fileio import read_user_file
from ...proof.onestep import OneStepCheck, StepMismatch
from ...shipping.artifact import Artifact
from .reference import ScheduledLoop, ScheduledState, ScheduledTrace

REL = 1e-12  # float64 against float64: a few roundings on each quantity's magnitude


def state_columns(a: Artifact) -> list[str]:
    """Names of the state columns, in :meth:`ScheduledState.vector` order."""
    parts = (("d", a.n), ("up", a.m), ("yp", a.p), ("ep", a.q))
    return [f"{p}{i}" for p, k in parts for i in range(k)] + ["sh", "sf", "started"]


#: The arithmetic a scheduled trace can name in its first line.
NUMERICS = ("float64", "float32")


def format_trace(a: Artifact, trace: ScheduledTrace, t: np.ndarray | None = None, *, numeric: str | None = None) -> str:
    """The output CSV text of a scheduled replay (round-trip floats), after a ``# numeric=...`` line when
    ``numeric`` (:data:`NUMERICS`) is given."""
    m = a.m
    header = (["t"] if t is not None else []) + [f"u{i}" for i in range(m)] + [f"sat{i}" for i in range(m)]
    header += ["fault", "sigma", "sflags"] + state_columns(a)
    out = io.StringIO()
    if numeric is not None:
        out.write(f"# numeric={numeric}\n")
    out.write(",".join(header) + "\n")
    for k in range(trace.u.shape[0]):
        cells = ([repr(float(t[k]))] if t is not None else []) + [repr(float(v)) for v in trace.u[k]]
        cells += [str(int(s)) for s in trace.saturated[k]] + [str(int(trace.fault[k]))]
        cells += [repr(float(trace.sigma[k])), str(int(trace.sigma_flags[k]))]
        cells += [repr(float(v)) for v in trace.state[k]]
        out.write(",".join(cells) + "\n")
    return out.getvalue()


def read_trace(path: str | Path, a: Artifact) -> ScheduledTrace:
    """A scheduled replay output CSV back into a :class:`ScheduledTrace`, with the arithmetic its first line names
    (DataError when it is not one, or names another)."""
    path = Path(path)
    lines = read_user_file(path, what="comparison file", error=DataError).splitlines(keepends=True)
    head = 0
    while head < len(lines) and lines[head].startswith("#"):
        head += 1
    meta = dict(ln[1:].strip().partition("=")[::2] for ln in lines[:head])
    numeric = meta.get("numeric", "float64").strip()
    if numeric not in NUMERICS:
        raise DataError(
            f"comparison file {path} is a trace of a {numeric} law and artifact {a.name} is a scheduled float32 design:"
            " compare traces of its float64 law or of its C"
        )
    rows = list(csv.DictReader(io.StringIO("".join(lines[head:]))))
    try:
        col = lambda names, kind=float: np.array([[kind(r[c]) for c in names] for r in rows]).reshape(len(rows), -1)  # noqa: E731
        return ScheduledTrace(
            u=col([f"u{i}" for i in range(a.m)]),
            saturated=col([f"sat{i}" for i in range(a.m)], int).astype(bool),
            fault=col(["fault"], int).astype(bool).ravel(),
            sigma=col(["sigma"]).ravel(),
            sigma_flags=col(["sflags"], int).ravel(),
            state=col(state_columns(a)),
            numeric=numeric,
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(
            f"comparison file {path} is not a scheduled replay output of {a.name} (bad or missing {exc})"
        ) from None


def _state_from(a: Artifact, v: np.ndarray) -> ScheduledState:
    n, m, p, q = a.n, a.m, a.p, a.q
    cut = np.cumsum([n, m, p, q])
    return ScheduledState(v[: cut[0]].copy(), v[cut[0] : cut[1]].copy(), v[cut[1] : cut[2]].copy(),
                          v[cut[2] : cut[3]].copy(), float(v[-3]), float(v[-2]), bool(v[-1]))  # fmt: skip


def one_step_check(
    a: Artifact, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, trace: ScheduledTrace, *, float32: bool = False
) -> OneStepCheck:
    """Every step of ``trace`` against the scheduled law started from the trace's own previous state: the float64
    law within ``REL``, or with ``float32`` the C's float32 arithmetic, bit for bit."""
    from .model import ScheduledFloat32Loop

    Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
    N = Y.shape[0]
    if trace.u.shape[0] != N:
        raise DataError(f"the trace has {trace.u.shape[0]} steps, the samples {N}")
    law = ScheduledFloat32Loop(a) if float32 else ScheduledLoop(a)
    rel = 0.0 if float32 else REL
    prev = law.state.vector()
    span = np.where(a.u_max > a.u_min, a.u_max - a.u_min, 1.0)
    worst, failures, first, max_rel_u = {"u": 0.0, "state": 0.0}, 0, None, 0.0
    for k in range(N):
        law.state = _state_from(a, prev)
        res = law.step(Y[k], None if R is None else R[k], None if S is None else S[k])
        bad = _compare(k, res, law.state.vector(), trace, worst, rel)
        max_rel_u = max(max_rel_u, float(np.max(np.abs(trace.u[k] - res.u) / span)))
        if bad is not None:
            failures += 1
            first = first or bad
        prev = trace.state[k]
    return OneStepCheck(steps=N, failures=failures, first_failure=first, worst=worst, max_rel_u=max_rel_u)


def _compare(k, res, state, trace, worst, rel: float) -> StepMismatch | None:
    for name, got, want in (("fault", trace.fault[k], res.fault), ("sflags", trace.sigma_flags[k], res.sigma_flags)):
        if int(got) != int(want):
            return StepMismatch(k, name, float(got), float(want), 0.0)
    for i in np.flatnonzero(trace.saturated[k] != res.saturated):
        return StepMismatch(k, f"sat{i}", float(trace.saturated[k][i]), float(res.saturated[i]), 0.0)
    found = None
    for name, got, want in (("u", trace.u[k], res.u), ("state", trace.state[k], state)):
        bound = rel * (1.0 + np.abs(want))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(got == want, 0.0, np.abs(got - want) / bound)
        worst[name] = max(worst[name], float(np.max(ratio, initial=0.0)))
        over = np.flatnonzero(~(ratio <= 1.0))
        if over.size and found is None:
            i = int(over[0])
            found = StepMismatch(k, f"{name}{i}", float(got[i]), float(want[i]), float(bound[i]))
    return found
