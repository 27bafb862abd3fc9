"""The MPC step's instruction count at the cap, proved for every input on the hard-float cores (docs/design.md, "MPC":
the cost certificate; bench/mpc_cost.py prints it, tests/test_mpc_cost_bound.py checks it).

The argument, in two halves:

1. **The disassembly** of the image that is measured (:func:`branch_argument`, on
   :mod:`gainlink.firmware.branches`): of every conditional branch in ``gl_mpc_step`` and the functions it calls, the
   only ones the law's numbers decide are the tests of a non-finite sample (one side goes straight to ``refuse``) and
   the solver's stopping test in ``solve`` (decided by what ``slacks`` returned). Every other branch is decided by
   immediates, the pointers the caller passes and the addresses loaded through them (loops of fixed trip count, NULL
   tests), so it takes the same outcome on every call: the box projections and the command's clamp are selects (an IT
   block: a predicated instruction is counted whether or not its condition holds), not branches. A soft-float call
   (``gl_fmaf``, ``__aeabi_*``: paths that depend on the operands) or a call that passes the law's numbers to code
   outside the image makes the argument fail: the M0 and M3 are measured, not proved.
2. **The paths** that leaves (:func:`step_bound`): a step either refuses at one of the non-finite tests (a path of
   its own per test, the same count every time), or runs ``it`` iterations and stops (1 <= it <= cap: the step's
   fixed part F_stop plus ``it`` times one iteration's count I, the same instructions each iteration), or runs the
   cap and does not stop (F_cap + cap I). So every step's count is at most ``max(refuse paths, F_stop + cap I,
   F_cap + cap I)``. F_stop, F_cap and I are read off a measured run that takes every path kind (steps that stop at
   two different iteration counts, at least one capped step, a non-finite value in each sample and reference
   element); the run must fit those formulas exactly (every count of a kind equal), which checks the first half's
   conclusion on the image.

The bound holds for the image measured (its core, its compiler and flags, the tables' dimensions it was built for:
any numbers in tables of those dimensions, any samples, any warm start), under the premise stated in
:mod:`gainlink.firmware.branches` (an integer word loaded from memory and only moved, offset and compared is an
address).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...firmware.branches import Analysis, analyse_text, disassemble, straight_call
from ...firmware.cost import count_step_instructions
from ...shipping.artifact import Artifact
from ..flags import CAPPED

ROOT = "gl_mpc_step"
SOLVE = "solve"
STOP = frozenset({"ret:slacks"})
REFUSE = "refuse"
ITERATION = ("backward", "forward", "slacks")


@dataclass
class BranchArgument:
    """The disassembly half: the branches the numbers decide, each with its role, and what breaks the argument."""

    analysis: Analysis
    refuse_tests: list[str] = field(default_factory=list)
    stop_tests: list[str] = field(default_factory=list)
    violations: list[str] = field(default_factory=list)

    @property
    def holds(self) -> bool:
        """Whether the count of a step is fixed by its path kind (refused, stopped at ``it``, capped)."""
        return not self.violations

    def summary(self) -> dict:
        """JSON-ready: every conditional branch (fixed or which role), and why the argument fails if it does."""
        a = self.analysis
        return {
            "functions": a.functions,
            "conditional_branches": len(a.branches),
            "fixed_branches": sum(not b.data for b in a.branches),
            "refuse_tests": self.refuse_tests,
            "stop_tests": self.stop_tests,
            "violations": self.violations,
        }


def branch_argument(elf: Path) -> BranchArgument:
    """Classify every conditional branch of the MPC step in ``elf`` (module docstring, first half)."""
    funcs = disassemble(elf)
    analysis = analyse_text(funcs, ROOT)
    out = BranchArgument(analysis)
    out.violations += [f"soft-float: {s} (its paths depend on the operands)" for s in analysis.soft_float]
    out.violations += analysis.data_calls
    out.violations += [f"indirect branch: {s}" for s in analysis.indirect]
    for b in analysis.data_branches():
        sides = {straight_call(funcs, b.function, b.taken), straight_call(funcs, b.function, b.fallthrough)}
        where = f"{b.function} {b.insn.text}"
        if b.function == ROOT and REFUSE in sides:
            out.refuse_tests.append(where)
        elif b.function == SOLVE and b.origins == STOP:
            out.stop_tests.append(where)
        else:
            out.violations.append(f"decided by {', '.join(sorted(b.origins))}: {where}")
    if not out.stop_tests:
        out.violations.append(f"no stopping test found in {SOLVE} (is it still a function of its own?)")
    if not out.refuse_tests:
        out.violations.append(f"no non-finite test going to {REFUSE} found in {ROOT}")
    return out


@dataclass(frozen=True)
class StepBound:
    """The second half: the per-iteration count, the fixed parts per exit, the refuse paths, the bound."""

    per_iteration: int
    fixed_stop: int
    fixed_cap: int
    refuse_max: int
    cap: int
    bound: int
    measured_max: int

    def summary(self) -> dict:
        """JSON-ready."""
        return dict(self.__dict__)


class NotProved(ValueError):
    """The run does not take every path kind, or its counts do not fit the path formulas: no bound."""


def step_bound(counts, iterations, capped, refused, cap: int) -> StepBound:
    """The bound at the cap from a measured run (module docstring, second half): ``counts`` each step's
    instructions, ``iterations`` the solver's iterations, ``capped`` and ``refused`` the step's flags."""
    c = np.asarray(counts, dtype=np.int64)
    it = np.asarray(iterations, dtype=np.int64)
    cap_ = np.asarray(capped, dtype=bool)
    ref = np.asarray(refused, dtype=bool)
    stop = ~cap_ & ~ref
    if not ref.any() or not cap_.any() or len(set(it[stop].tolist())) < 2:
        raise NotProved(
            "the run must hold a refused step, a capped step and steps that stop at two different iteration counts "
            f"(refused {int(ref.sum())}, capped {int(cap_.sum())}, stopped at {sorted(set(it[stop].tolist()))})"
        )
    i0, i1 = np.flatnonzero(stop)[[np.argmin(it[stop]), np.argmax(it[stop])]]
    per_iter, rem = divmod(int(c[i1] - c[i0]), int(it[i1] - it[i0]))
    fixed_stop = c[stop] - it[stop] * per_iter
    fixed_cap = c[cap_] - it[cap_] * per_iter
    if rem or len(set(fixed_stop.tolist())) != 1 or len(set(fixed_cap.tolist())) != 1 or np.any(it[cap_] != cap):
        raise NotProved(
            "the counts do not fit fixed part + iterations x one iteration: "
            f"stop fixed parts {sorted(set(fixed_stop.tolist()))}, capped {sorted(set(fixed_cap.tolist()))}"
        )
    f_stop, f_cap = int(fixed_stop[0]), int(fixed_cap[0])
    refuse_max = int(c[ref].max())
    bound = max(refuse_max, f_stop + cap * per_iter, f_cap + cap * per_iter)
    return StepBound(per_iter, f_stop, f_cap, refuse_max, cap, bound, int(c.max()))


def refuse_samples(p: int, q: int, y: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One step per sample and reference element with that element NaN and the others ``y``, ``r``: every
    non-finite test the image has is taken by one of them (a test is reached by a NaN in an element no earlier test
    covers)."""
    Y, R = np.tile(y, (p + q, 1)), np.tile(r, (p + q, 1))
    for k in range(p):
        Y[k, k] = np.nan
    for j in range(q):
        R[p + j, j] = np.nan
    return Y, R


@dataclass(frozen=True)
class Measured:
    """A replay through the image: every step's instructions, and the iterations, capped and refused flags and the
    law's state after each step of the host C (the image's run bit for bit, tests/test_mpc.py)."""

    counts: np.ndarray
    iterations: np.ndarray
    capped: np.ndarray
    refused: np.ndarray
    state: np.ndarray


def measure(a: Artifact, elf: Path, *, board: str, Y: np.ndarray, R: np.ndarray) -> Measured:
    """Replay ``Y``, ``R`` through ``elf`` on ``board`` from the law's start, counting every step."""
    from .. import law_of

    cost = count_step_instructions(elf, a, Y=Y, R=R, board=board, each=True)
    trace = law_of(a).replay(a, "native", Y, R)
    if len(cost.each) != len(Y):
        raise NotProved(f"{len(cost.each)} step counts for {len(Y)} samples")
    flags = np.asarray(trace.flags)
    return Measured(
        counts=np.asarray(cost.each, dtype=np.int64),
        iterations=np.asarray(trace.iterations),
        capped=(flags & CAPPED) != 0,
        refused=np.asarray(trace.fault),
        state=np.asarray(trace.state),
    )


def bound_of(m: Measured, cap: int) -> StepBound:
    """:func:`step_bound` of a measured run."""
    return step_bound(m.counts, m.iterations, m.capped, m.refused, cap)
