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
   F_cap + cap I)``. I is the three passes' counts (each the same on every call of the run, checked) plus solve's
   own loop body, counted on the disassembly (:func:`iteration_instructions`); F_stop and F_cap are read off a run
   that takes every path kind (a step that stops, a capped step, a non-finite value in each sample and reference
   element), and the run must fit the formulas exactly (every step of a kind gives the same fixed part), which
   checks the first half's conclusion on the image.

The bound holds for the image measured (its core, its compiler and flags, the tables' dimensions it was built for:
any numbers in tables of those dimensions, any samples, any warm start), under the premise stated in
:mod:`gainlink.firmware.branches` (an integer word loaded from memory and only moved, offset and compared is an
address).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...firmware.branches import (
    Analysis,
    analyse_text,
    branch_target,
    disassemble,
    is_conditional_branch,
    straight_call,
)
from ...firmware.cost import count_calls, count_step_instructions
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


def step_bound(counts, iterations, capped, refused, cap: int, per_iteration: int) -> StepBound:
    """The bound at the cap from a measured run (module docstring, second half): ``counts`` each step's
    instructions, ``iterations`` the solver's iterations, ``capped`` and ``refused`` the step's flags,
    ``per_iteration`` one iteration's instructions (:func:`iteration_instructions`)."""
    c = np.asarray(counts, dtype=np.int64)
    it = np.asarray(iterations, dtype=np.int64)
    cap_ = np.asarray(capped, dtype=bool)
    ref = np.asarray(refused, dtype=bool)
    stop = ~cap_ & ~ref
    if not (ref.any() and cap_.any() and stop.any()):
        raise NotProved(
            "the run must hold a refused step, a capped step and a step that stops "
            f"(refused {int(ref.sum())}, capped {int(cap_.sum())}, stopped {int(stop.sum())})"
        )
    fixed_stop = sorted(set((c[stop] - it[stop] * per_iteration).tolist()))
    fixed_cap = sorted(set((c[cap_] - it[cap_] * per_iteration).tolist()))
    if len(fixed_stop) != 1 or len(fixed_cap) != 1 or np.any(it[cap_] != cap):
        raise NotProved(
            f"the counts do not fit fixed part + iterations x {per_iteration}: "
            f"fixed parts of the steps that stop {fixed_stop}, of the capped ones {fixed_cap}"
        )
    refuse_max = int(c[ref].max())
    bound = max(refuse_max, (max(fixed_stop[0], fixed_cap[0]) + cap * per_iteration))
    return StepBound(per_iteration, fixed_stop[0], fixed_cap[0], refuse_max, cap, bound, int(c.max()))


def loop_instructions(funcs: dict, function: str = SOLVE) -> int:
    """The instructions ``function``'s loop runs of its own each time round (its calls' excluded): from the target of
    its one backward conditional branch to that branch, which must be straight code on the way round (every other
    branch in it leaves the loop, forward)."""
    insns = [i for i in funcs[function] if not i.mnemonic.startswith(".")]
    back = [
        (i, t[0]) for i in insns if is_conditional_branch(i.mnemonic) and (t := branch_target(i)) and t[0] <= i.address
    ]
    if len(back) != 1:
        raise NotProved(f"{function} has {len(back)} backward branches: its loop is not one straight body")
    end, head = back[0][0].address, back[0][1]
    body = [i for i in insns if head <= i.address <= end]
    for i in body[:-1]:
        t = branch_target(i)
        if i.mnemonic.split(".")[0] == "b" or (
            is_conditional_branch(i.mnemonic) and (t is None or head <= t[0] <= end)
        ):
            raise NotProved(f"{function}'s loop is not straight at {i.text}")
    return len(body)


def iteration_instructions(a: Artifact, elf: Path, *, board: str, Y: np.ndarray, R: np.ndarray) -> int:
    """One iteration's instructions in ``elf``: ``backward``, ``forward`` and ``slacks`` (each call of each the same
    count over the replay of ``Y``, ``R``, or :class:`NotProved`) and solve's own loop (:func:`loop_instructions`)."""
    total = loop_instructions(disassemble(elf))
    for part in ITERATION:
        cost = count_calls(elf, a, symbol=part, Y=Y, R=R, board=board)
        if cost.cheapest != cost.dearest:
            raise NotProved(f"{part} took {cost.cheapest} to {cost.dearest} instructions a call: not fixed")
        total += cost.dearest
    return total


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


def bound_of(m: Measured, cap: int, per_iteration: int) -> StepBound:
    """:func:`step_bound` of a measured run."""
    return step_bound(m.counts, m.iterations, m.capped, m.refused, cap, per_iteration)
