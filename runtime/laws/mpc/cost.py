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
   outside the image makes this argument fail: the M0 and M3 take the soft-float argument below.
2. **The paths** that leaves (:func:`step_bound`): a step either refuses at one of the non-finite tests (a path of
   its own per test, the same count every time), or runs ``it`` iterations and stops (1 <= it <= cap: the step's
   fixed part F_stop plus ``it`` times one iteration's count I, the same instructions each iteration), or runs the
   cap and does not stop (F_cap + cap I). So every step's count is at most ``max(refuse paths, F_stop + cap I,
   F_cap + cap I)``. I is the three passes' counts (each the same on every call of the run, checked) plus solve's
   own loop body, counted on the disassembly (:func:`iteration_instructions`); F_stop and F_cap are read off a run
   that takes every path kind (a step that stops, a capped step, a non-finite value in each sample and reference
   element), and the run must fit the formulas exactly (every step of a kind gives the same fixed part), which
   checks the first half's conclusion on the image.

**Soft float** (the M0, the M3: :func:`soft_step_bound`): the multiply-adds and compares are calls of ``gl_fmaf`` and
libgcc's routines, whose paths depend on their operands, and the box clamps are branches on a compare's result. Each
routine's graph is loop-free but for libgcc's normalisation of a subnormal operand in the M3's ``__aeabi_fmul``
(:func:`normalisation_loops`: at most 22 times back, premise :data:`LOOP_PREMISE`), so its dearest call is its
longest path, those loops at their most (:mod:`gainlink.firmware.paths`). A pass (``backward``, ``forward``,
``slacks``) may have branches the numbers decide only if they are detours: decided by the call right before them,
every path from their two sides meeting again within a few instructions, loop-free, each making the same soft-float
calls (a clamp: a compare, and a move or a second compare; :func:`detour`). Its path and its calls are then the same
on every call, so a measured run splits its count into its own instructions (the least
measured, plus one detour's difference per execution) and its calls, each charged at its routine's bound
(:func:`soft_pass`). One iteration: solve's loop body plus the passes' bounds. The fixed part, from steps that do not
refuse, the same way: ``gl_mpc_step``'s branches before ``solve`` must be its non-finite tests (an unordered or a
greater-than compare: premise, a finite sample decides them the same way every step, as the C's ``isfinite`` tests
are), those after it detours. A refused step: the heaviest path of ``gl_mpc_step`` to its call of ``refuse`` and on to
its return (the tests must be loop-free), ``refuse``'s copy at its measured fixed count. The bound at the cap is
``max(refuse, fixed + cap x iteration)``; every routine at its dearest path makes it loose (about 1.9x on the M0
pendulum, 3.9x on the M3, whose ``__aeabi_fmul`` is charged with both operands subnormal), but it holds for any
operands.

The bound holds for the image measured (its core, its compiler and flags, the tables' dimensions it was built for:
any numbers in tables of those dimensions, any samples, any warm start), under the premises stated in
:mod:`gainlink.firmware.branches` (an integer word loaded from memory and only moved, offset and compared is an
address; an index added to a frame address is not negative: :data:`PREMISE`, :data:`FRAME_PREMISE`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...firmware.branches import (
    COPIES,
    SOFT_FLOAT,
    Analysis,
    analyse_text,
    branch_target,
    disassemble,
    is_conditional_branch,
    straight_call,
)
from ...firmware.cost import count_calls, count_step_instructions
from ...firmware.paths import Bounds, Unbounded, heaviest, reachable, reaching
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


@dataclass(frozen=True)
class SoftPass:
    """One pass of an iteration on a soft-float core: its own instructions (the least a call ran, the most its
    compare-decided skips can add), the soft-float calls it makes per call and each one's proved dearest call."""

    own: int
    skips: int
    calls: dict[str, int]
    routine_bounds: dict[str, int]

    @property
    def bound(self) -> int:
        """The most one call of the pass executes, for any operands."""
        return self.own + self.skips + sum(n * self.routine_bounds[f] for f, n in self.calls.items())


#: libgcc's normalisation of a subnormal operand on the M3 (ieee754-sf.S, ``__aeabi_fmul``): shift the word left by
#: one until its bit 23 is set, counting the exponent down: ``ittt eq; lsleq rX, rX, #1; tsteq rX, #0x800000;
#: subeq rY, #1; beq`` back to the ``ittt``.
NORMALISE = (r"itt+", r"lsl(?:eq)?", r"tst(?:eq)?", r"sub(?:eq)?", r"beq")
#: How many times its ``beq`` goes back, at most: the operand's mantissa is nonzero (zero operands leave before it: the
#: libgcc source, premise) and below 2**23, its top bit at 0..22 after the first shift has pushed the sign out, so
#: bit 23 is set after at most 23 shifts, the last of which falls through.
NORMALISE_TRIPS = 22
LOOP_PREMISE = (
    "libgcc's normalisation loop of a subnormal operand (shift left by one until bit 23 is set) goes back at most "
    f"{NORMALISE_TRIPS} times: its mantissa is nonzero (zero operands leave before it)"
)


def normalisation_loops(funcs: dict) -> dict[tuple[str, int], int]:
    """Every loop of the soft-float routines that is libgcc's normalisation of a subnormal operand
    (:data:`NORMALISE`: the shift by one and the test of bit 23 on the same register), keyed as
    :class:`~gainlink.firmware.paths.Bounds` takes them, each bounded by :data:`NORMALISE_TRIPS`."""
    out = {}
    for name, insns in funcs.items():
        if not SOFT_FLOAT.match(name):
            continue
        code = [i for i in insns if not i.mnemonic.startswith(".")]
        for k in range(len(NORMALISE) - 1, len(code)):
            body = code[k - len(NORMALISE) + 1 : k + 1]
            if not all(re.fullmatch(p, i.mnemonic.split(".")[0]) for p, i in zip(NORMALISE, body)):
                continue
            shift, test = body[1].operands.replace(" ", "").split(","), body[2].operands.replace(" ", "").split(",")
            target = branch_target(body[-1])
            if (target and target[0] == body[0].address and shift[0] == shift[1] == test[0] and shift[2] == "#1"
                    and test[1] == "#8388608"):  # fmt: skip
                out[name, body[-1].address] = NORMALISE_TRIPS
    return out


def routine_bounds(funcs: dict, given: dict[str, int] | None = None) -> Bounds:
    """The dearest call of each routine of ``funcs`` (:class:`~gainlink.firmware.paths.Bounds`), libgcc's
    normalisation loops bounded (:func:`normalisation_loops`)."""
    return Bounds(funcs, given, normalisation_loops(funcs))


def _paths(insns: list, k: int | None, index: dict, limit: int = 24) -> list[tuple[list[int], list[str]]]:
    """Every path from ``insns[k]`` inside the function (both sides of each conditional branch, unconditional branches
    followed), each up to ``limit`` instructions, a return or a tail call: its addresses and the functions it calls."""
    out: list[tuple[list[int], list[str]]] = []
    todo: list[tuple[int | None, list[int], list[str]]] = [(k, [], [])]
    while todo:
        k, addrs, calls = todo.pop()
        while k is not None and k < len(insns) and len(addrs) < limit:
            i = insns[k]
            base, target = i.mnemonic.split(".")[0], branch_target(i)
            addrs = [*addrs, i.address]
            if base == "bl":
                calls = [*calls, target[1] if target else "?"]
            elif base == "b" or is_conditional_branch(i.mnemonic):
                inside = index.get(target[0]) if target else None
                if base == "b":
                    k = inside  # a tail call (None) ends the path
                    continue
                todo.append((inside, addrs, calls))  # the taken side (None: it leaves the function)
            elif base == "bx" or i.operands.startswith("pc") or ("{" in i.operands and "pc" in i.operands):
                break  # a return (bx lr, pop {..., pc}, ldr pc, [sp], #8)
            k += 1
        out.append((addrs, calls))
    return out


def detour(funcs: dict, function: str, branch) -> tuple[str, int]:
    """A branch the law's numbers decide, if it is a detour: decided by what the call right before it returned
    (straight code back to that ``bl``), and every path from its two sides (through the branches after it, both
    sides of each) meets again within a few instructions, loop-free, each making the same soft-float calls (a clamp
    is one: compare, and maybe move or compare again). Returns (the deciding routine, the most instructions one path
    runs more than another, calls aside); :class:`NotProved` otherwise."""
    insns = [i for i in funcs[function] if not i.mnemonic.startswith(".")]
    index = {i.address: k for k, i in enumerate(insns)}
    targets = {t[0] for t in map(branch_target, insns) if t}
    k = index[branch.insn.address]
    j = k - 1
    while j >= 0 and insns[j].mnemonic.split(".")[0] != "bl":
        if insns[j].address in targets or is_conditional_branch(insns[j].mnemonic) or insns[j].mnemonic[0] == "b":
            raise NotProved(f"{function} {branch.insn.text}: not straight after the call that decides it")
        j -= 1
    callee = (branch_target(insns[j]) or (0, "?"))[1] if j >= 0 else "?"
    if branch.origins != frozenset({f"ret:{callee}"}):
        raise NotProved(f"{function} {branch.insn.text}: decided by {sorted(branch.origins)}, not by {callee}")
    paths = _paths(insns, index.get(branch.taken), index) + _paths(insns, k + 1, index)
    meet = next((a for a in paths[0][0] if all(a in p for p, _ in paths)), None)
    if meet is None:
        raise NotProved(f"{function} {branch.insn.text}: its sides do not meet")
    cut = [(p[: p.index(meet)], c[: sum(1 for a in p[: p.index(meet)] if _is_call(insns[index[a]]))]) for p, c in paths]
    if any(len(set(p)) != len(p) for p, _ in cut):
        raise NotProved(f"{function} {branch.insn.text}: a loop before its sides meet")
    if len({tuple(sorted(c)) for _, c in cut}) != 1 or not all(SOFT_FLOAT.match(f) for _, c in cut for f in c):
        raise NotProved(f"{function} {branch.insn.text}: its sides make different calls before they meet")
    lengths = [len(p) for p, _ in cut]
    return callee, max(lengths) - min(lengths)


def _is_call(insn) -> bool:
    return insn.mnemonic.split(".")[0] == "bl"


def _reached(funcs: dict, analysis: Analysis, part: str, stop: frozenset[str] = frozenset()) -> set[str]:
    """The functions ``part`` calls in the image, and those they call, but for the soft-float routines and ``stop``
    (not entered), ``part`` included."""
    where = {i.address: f for f, insns in funcs.items() for i in insns}
    reached, todo = {part}, [part]
    while todo:
        f = todo.pop()
        for at, callee in analysis.calls.items():
            if (where.get(at) == f and callee in funcs and callee not in reached | stop
                    and not SOFT_FLOAT.match(callee)):  # fmt: skip
                reached.add(callee)
                todo.append(callee)
    return reached


def _only_soft_float_decides(
    funcs: dict, analysis: Analysis, part: str, handled: frozenset[str] = frozenset()
) -> set[str]:
    """No function ``part`` reaches other than through a soft-float routine has a branch the numbers decide (``part``
    itself and ``handled`` aside: their branches are argued apart), no jump is indirect and no call passes the numbers
    outside the image. Returns those functions, ``part`` included."""
    if analysis.indirect or analysis.data_calls:
        raise NotProved(f"{part}: {(analysis.indirect + analysis.data_calls)[0]}")
    reached = _reached(funcs, analysis, part)
    for f in sorted(reached - {part} - handled):
        if analysis.data_branches(f):
            raise NotProved(f"{f}, called by {part}, has branches the numbers decide")
    return reached


def soft_pass(a: Artifact, elf: Path, part: str, *, board: str, Y: np.ndarray, R: np.ndarray) -> SoftPass:
    """The most one call of ``part`` executes on a soft-float core, for any operands (module docstring, "soft float").

    The pass's only branches the numbers decide must be skips (:func:`_skip`), so its path and its sequence of
    soft-float calls are the same on every call: each routine's calls over the run split into equal consecutive
    runs, one per call of the pass; what is left of each call's count is the pass's own instructions, which the skips
    make vary by at most one skipped side per execution (an execution per call of the routine that decides it)."""
    funcs = disassemble(elf)
    analysis = analyse_text(funcs, part)
    bounds = routine_bounds(funcs)
    reached = _only_soft_float_decides(funcs, analysis, part)  # part and the helpers it calls (backward_stage)
    here = {i.address for f in reached for i in funcs[f]}
    callees = sorted({f for at, f in analysis.calls.items() if at in here and SOFT_FLOAT.match(f)})
    total = count_calls(elf, a, symbol=part, Y=Y, R=R, board=board, each=True)
    own = np.asarray(total.each, dtype=np.int64)
    calls: dict[str, int] = {}
    for f in callees:
        c = count_calls(elf, a, symbol=f, Y=Y, R=R, board=board, each=True, callers=tuple(sorted(reached)))
        if c.calls % total.calls:
            raise NotProved(f"{part} made {c.calls} calls of {f} in {total.calls} calls: not the same each time")
        calls[f] = c.calls // total.calls
        own -= np.asarray(c.each, dtype=np.int64).reshape(total.calls, calls[f]).sum(axis=1)
    skips = 0
    for b in analysis.data_branches(part):
        callee, n = detour(funcs, part, b)
        skips += n * calls[callee]
    if int(own.max() - own.min()) > skips:
        raise NotProved(f"{part}'s own count ranged over {own.min()}..{own.max()}, more than its skips allow")
    return SoftPass(int(own.min()), skips, calls, {f: bounds(f) for f in callees})


def soft_iteration_bound(a: Artifact, elf: Path, *, board: str, Y: np.ndarray, R: np.ndarray) -> int:
    """The most one iteration executes on a soft-float core, for any operands: solve's own loop body plus each pass's
    :func:`soft_pass` bound."""
    funcs = disassemble(elf)
    return loop_instructions(funcs) + sum(soft_pass(a, elf, p, board=board, Y=Y, R=R).bound for p in ITERATION)


def refuse_bound(a: Artifact, elf: Path, *, board: str, y: np.ndarray, r: np.ndarray) -> int:
    """The most a step that refuses executes on a soft-float core, for any samples: the heaviest path of
    ``gl_mpc_step``'s graph from its entry to a call of ``refuse`` (through the instructions that reach it: the
    non-finite tests must be loop-free) and from there to its return, every call at its callee's bound and the copies
    ``refuse`` makes at their count measured on a refused step (the same every call: a fixed length)."""
    funcs = disassemble(elf)
    Yn, Rn = refuse_samples(a.p, a.q, y, r)
    given = {}
    for copy in sorted({(branch_target(i) or (0, ""))[1] for i in funcs[REFUSE]} & COPIES):
        cost = count_calls(elf, a, symbol=copy, Y=Yn, R=Rn, board=board, callers=(REFUSE,))
        if cost.cheapest != cost.dearest:
            raise NotProved(f"{REFUSE}'s {copy} took {cost.cheapest} to {cost.dearest} instructions a call")
        given[copy] = cost.dearest
    bounds = routine_bounds(funcs, given)
    graph = bounds.graph(ROOT)
    nodes = reachable(graph, 0)
    worst = 0
    for c in (k for k in nodes if graph[k].callee == REFUSE):
        to = heaviest(ROOT, graph, reaching(graph, c, nodes), 0, bounds.weight, end=c)
        after = heaviest(ROOT, graph, reachable(graph, c), c, bounds.weight)
        worst = max(worst, to + after - bounds.weight(graph[c]))
    if not worst:
        raise NotProved(f"{ROOT} never calls {REFUSE}")
    return worst


@dataclass(frozen=True)
class SoftStepBound:
    """The bound at the cap on a soft-float core: one iteration's bound, the fixed part's, a refused step's."""

    per_iteration: int
    fixed: int
    refuse: int
    cap: int
    bound: int
    measured_max: int
    passes: dict

    def summary(self) -> dict:
        """JSON-ready."""
        return dict(self.__dict__)


def _root_detours(funcs: dict, analysis: Analysis) -> dict[str, int]:
    """The most instructions the detours of ``gl_mpc_step`` after its call of ``solve`` add to a step (one side each,
    per execution: one per call of the routine deciding it); the branches before ``solve`` must be the non-finite
    tests (decided by an unordered or a greater-than compare, one side reaching ``refuse``)."""
    at_solve = next(a for a, f in analysis.calls.items() if f == SOLVE and a in {i.address for i in funcs[ROOT]})
    extra: dict[str, int] = {}
    for b in analysis.data_branches(ROOT):
        if b.insn.address < at_solve:
            if not b.origins <= {"ret:__aeabi_fcmpun", "ret:__aeabi_fcmpgt"}:
                raise NotProved(f"{ROOT} {b.insn.text}: before {SOLVE}, decided by {sorted(b.origins)}")
            continue
        callee, n = detour(funcs, ROOT, b)
        extra[callee] = extra.get(callee, 0) + n
    return extra


def soft_step_bound(a: Artifact, elf: Path, *, board: str, Y: np.ndarray, R: np.ndarray) -> SoftStepBound:
    """The bound at the cap on a soft-float core (module docstring, "soft float") from ``Y``, ``R``: steps that do
    not refuse, some capped and some stopping early."""
    funcs = disassemble(elf)
    analysis = analyse_text(funcs, ROOT)
    _only_soft_float_decides(funcs, analysis, ROOT, frozenset({SOLVE, REFUSE, *ITERATION}))
    stops = analysis.data_branches(SOLVE)
    if len(stops) != 1 or stops[0].origins != STOP:
        raise NotProved(f"{SOLVE}'s branches the numbers decide are not its one stopping test")
    m = measure(a, elf, board=board, Y=Y, R=R)
    if m.refused.any() or not m.capped.any() or m.capped.all():
        raise NotProved("the run must not refuse, and must hold capped steps and steps that stop early")
    passes = {p: soft_pass(a, elf, p, board=board, Y=Y, R=R) for p in ITERATION}
    body = loop_instructions(funcs)
    per_iteration = body + sum(p.bound for p in passes.values())
    own = m.counts - m.iterations * body
    for p in ITERATION:  # each step's calls of the pass: its iterations' worth, in order
        each = np.asarray(count_calls(elf, a, symbol=p, Y=Y, R=R, board=board, each=True).each, dtype=np.int64)
        if len(each) != int(m.iterations.sum()):
            raise NotProved(f"{p} was called {len(each)} times in {int(m.iterations.sum())} iterations")
        own -= np.add.reduceat(each, np.r_[0, np.cumsum(m.iterations)[:-1]])
    detours = _root_detours(funcs, analysis)
    own_code = _reached(funcs, analysis, ROOT, frozenset({SOLVE, REFUSE, *ITERATION}))  # the step and its helpers
    here = {i.address for f in own_code for i in funcs[f]}
    bounds = routine_bounds(funcs)
    calls: dict[str, int] = {}
    for f in sorted({f for at, f in analysis.calls.items() if at in here and SOFT_FLOAT.match(f)}):
        c = count_calls(elf, a, symbol=f, Y=Y, R=R, board=board, each=True, callers=tuple(sorted(own_code)))
        if c.calls % len(Y):
            raise NotProved(f"{ROOT} made {c.calls} calls of {f} in {len(Y)} steps: not the same each step")
        calls[f] = c.calls // len(Y)
        own -= np.asarray(c.each, dtype=np.int64).reshape(len(Y), calls[f]).sum(axis=1)
    slack = sum(n * calls[f] for f, n in detours.items())
    for kind in (m.capped, ~m.capped):
        if int(own[kind].max() - own[kind].min()) > slack:
            raise NotProved(f"the fixed part ranged over {own[kind].min()}..{own[kind].max()}, more than {slack}")
    fixed = int(own.max()) + slack + sum(n * bounds(f) for f, n in calls.items())
    cap = a.mpc.max_iter
    refuse = refuse_bound(a, elf, board=board, y=Y[-1], r=R[-1])
    bound = max(refuse, fixed + cap * per_iteration)
    return SoftStepBound(per_iteration, fixed, refuse, cap, bound, int(m.counts.max()),
                         {p: v.bound for p, v in passes.items()})  # fmt: skip


# -- the bound of an image, as the cost benchmark and `pil run` report it ------------------------------------------

LEGS = ((60, 1.0), (30, -1.5))  # closed-loop legs: steps, the start's offset (the law keeps its state across legs)
SOFT_STEPS = 3  # a soft-float core runs ~4M instructions a step through gl_fmaf: its bound is taken on a short run
PREMISE = "a word an integer register loads and only moves, offsets and compares is an address"
FRAME_PREMISE = "an index added to a stack frame's address is not negative (a local array is not indexed below it)"
SOFT_PREMISE = "the step's branches before solve are its non-finite tests"


def closed_loop_samples(a: Artifact, legs=LEGS) -> tuple[np.ndarray, np.ndarray]:
    """The host C around the design's sampled plant, one leg per (steps, offset) from a start that saturates the
    inputs (quadrotor: x, y and z off by half the offset; pendulum: the cart), the law's state kept across legs."""
    from .. import law_of

    law = law_of(a)
    plant, c = law.plant(a), law.native(a)
    Y = []
    for steps, off in legs:
        x0 = np.zeros(a.n)
        x0[: 3 if a.n == 12 else 1] = off / 2 if a.n == 12 else off
        plant.reset(x0)
        for _ in range(steps):
            Y.append(plant.outputs())
            plant.advance(c.step(Y[-1], law.r_op(a), np.zeros(0)).u)
    return np.array(Y), np.tile(law.r_op(a), (len(Y), 1))


def prove(a: Artifact, elf: Path, *, board: str, arg: BranchArgument | None = None) -> StepBound | SoftStepBound:
    """The bound at the cap of ``elf`` (``arg``: its :func:`branch_argument`, computed if not given): on a hard-float
    core from the closed loop of :data:`LEGS` and a NaN in each sample and reference element (:func:`bound_of`), on a
    soft-float one from the loop's first :data:`SOFT_STEPS` steps (:func:`soft_step_bound`); :class:`NotProved`
    saying why otherwise."""
    arg = branch_argument(elf) if arg is None else arg
    Y, R = closed_loop_samples(a)
    if not arg.holds and arg.analysis.soft_float:
        try:
            return soft_step_bound(a, elf, board=board, Y=Y[:SOFT_STEPS], R=R[:SOFT_STEPS])
        except Unbounded as exc:  # a routine's dearest path is not bounded: no bound
            raise NotProved(str(exc)) from exc
    if not arg.holds:
        raise NotProved("; ".join(arg.violations[:2]))
    Yn, Rn = refuse_samples(a.p, a.q, Y[-1], R[-1])
    Y, R = np.vstack([Y, Yn]), np.vstack([R, Rn])
    run = measure(a, elf, board=board, Y=Y, R=R)
    return bound_of(run, a.mpc.max_iter, iteration_instructions(a, elf, board=board, Y=Y, R=R))


def premises(elf: Path, *, soft: bool) -> list[str]:
    """The premises a bound of ``elf`` rests on, to be printed with it (``soft``: proved by :func:`soft_step_bound`)."""
    out = [PREMISE, FRAME_PREMISE, SOFT_PREMISE] if soft else [PREMISE, FRAME_PREMISE]
    if soft and normalisation_loops(disassemble(elf)):
        out.append(LOOP_PREMISE)
    return out


def bound_block(a: Artifact, elf: Path, *, board: str, core: str) -> dict:
    """``pil.json``'s ``instructions_per_step.bound`` for the image ``elf`` on ``core``: the bound per iteration and
    per step at the cap (``per_step = fixed + cap x per_iteration``, or a refused step's when that is dearer), whether
    it is proved and what it covers; ``proved`` false, no figure and why when the argument fails (then measured,
    not proved)."""
    try:
        b = prove(a, elf, board=board)
    except NotProved as exc:
        return {"proved": False, "core": core, "covers": f"measured, not proved on {core}: {exc}"}
    soft = isinstance(b, SoftStepBound)
    fixed = b.fixed if soft else max(b.fixed_stop, b.fixed_cap)
    refuse = b.refuse if soft else b.refuse_max
    how = ("soft float: every float routine the step calls charged at its longest path, the compare-decided branches "
           "at their longer side; loose" if soft else
           "the law's numbers decide only the non-finite tests and the stopping test (the disassembly), and a run "
           "fits fixed part + iterations x one iteration exactly")  # fmt: skip
    return {
        "proved": True,
        "core": core,
        "per_iteration": int(b.per_iteration),
        "fixed": int(fixed),
        "cap": int(b.cap),
        "refused_step": int(refuse),
        "per_step": int(b.bound),
        "covers": (
            f"every input (samples, references, warm start, numbers in tables of horizon {a.mpc.horizon}, "
            f"{a.mpc.nx} states, {a.m} inputs, {a.mpc.nc} box rows) on this image: {core}, its compiler "
            f"and flags; {how}"
        ),
        "premises": premises(elf, soft=soft),
    }
