"""The one-step check of an MPC trace: each step from the trace's own previous state, with the trace's own iteration
count, through the law in an arithmetic (bit for bit against the float32 model, within the solver's tolerance of the
float64 algorithm)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import flags
from .arith import Arith
from .step import MpcLoop, MpcTrace


@dataclass(frozen=True)
class StepMismatch:
    """The first step where a trace left what it is checked against."""

    k: int
    what: str

    def describe(self, name: str) -> str:
        return f"step {self.k} of {name}: {self.what}"


@dataclass(frozen=True)
class MpcOneStep:
    """A one-step check of an MPC trace: ``steps`` checked, the first mismatch (None: every step held) and the
    largest deviation of the command relative to each input's limit span."""

    steps: int
    first_failure: StepMismatch | None
    max_rel_u: float

    @property
    def passed(self) -> bool:
        return self.first_failure is None

    def summary(self) -> str:
        verdict = "every step holds" if self.passed else "FAILED"
        return f"{self.steps} steps, {verdict}; max |du| {self.max_rel_u:.3g} of the limit span"


def one_step_check(artifact: Any, Y, R, trace: MpcTrace, ar: Arith, *, exact: bool) -> MpcOneStep:
    """Each step of ``trace`` from the trace's own previous state through the law in ``ar``, with the trace's own
    iteration count: ``exact`` asks for the same bits (commands, flags, saturation, iterations, state), else the
    command within the solver's tolerance."""
    a = artifact
    loop = MpcLoop(a, ar)
    span = a.u_max - a.u_min
    worst, eps = 0.0, a.mpc.eps["pu"]
    for k in range(len(Y)):
        if k:
            loop.set_state(trace.state[k - 1])
        it = int(trace.iterations[k]) or None
        res = loop.step(Y[k], R[k], iterations=None if exact else it)
        if res.fault:
            got = (trace.flags[k] & flags.FAULT) != 0 and np.array_equal(res.u, trace.u[k])
            if not got:
                return MpcOneStep(k + 1, StepMismatch(k, "a refused sample answered otherwise"), worst)
            continue
        worst = max(worst, float(np.max(np.abs(res.u - trace.u[k]) / span)))
        if exact:
            answer = (res.sat, res.flags, res.iterations)
            same = answer == (trace.sat[k], trace.flags[k], trace.iterations[k])
            if not (same and np.array_equal(res.u, trace.u[k]) and np.array_equal(loop.state(), trace.state[k])):
                what = f"not bit for bit (u {res.u}, iterations {res.iterations}; the trace {trace.u[k]}, "
                return MpcOneStep(k + 1, StepMismatch(k, what + f"{trace.iterations[k]})"), worst)
        elif np.any(np.abs(res.u - trace.u[k]) > eps):
            what = f"u {trace.u[k]} is {np.abs(res.u - trace.u[k])} from the float64 algorithm's {res.u}"
            return MpcOneStep(k + 1, StepMismatch(k, what + f", beyond the tolerance {eps}"), worst)
    return MpcOneStep(len(Y), None, worst)
