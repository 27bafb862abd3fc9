"""The MPC step's instruction bound at the cap is a proof on the hard-float cores (gainlink.laws.mpc.cost): the
disassembly of the image leaves only the non-finite tests and the stopping test to the numbers, the measured run fits
fixed part + iterations x one iteration exactly, and no input found breaks the bound."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from gainlink.firmware.branches import analyse_text, disassemble, parse
from gainlink.firmware.build import replay_image
from gainlink.firmware.cost import count_calls
from gainlink.firmware.paths import Bounds, Unbounded
from gainlink.laws import design, law_of
from gainlink.laws.mpc.cost import (
    FRAME_PREMISE,
    LOOP_PREMISE,
    PREMISE,
    SOFT_PREMISE,
    NotProved,
    bound_block,
    bound_of,
    branch_argument,
    detour,
    iteration_instructions,
    measure,
    normalisation_loops,
    refuse_samples,
    routine_bounds,
    soft_step_bound,
)
from gainlink.shipping.artifact import from_dict
from gainlink.spec import load_spec
from support.paths import EXAMPLES

BOARD = "mps2-an386"
#: (design, target, board, the closed loop's legs: steps, offset); the M4F pendulum in make test, the rest in the matrix
CASES = [
    ("pendulum_mpc", "cortex-m4", BOARD, [(60, 1.0), (30, -1.5)]),
    *[
        pytest.param("pendulum_mpc", t, b, [(60, 1.0), (30, -1.5)], marks=pytest.mark.matrix)
        for t, b in (("cortex-m7", "mps2-an500"), ("cortex-m33", "mps2-an505"), ("cortex-m55", "mps3-an547"))
    ],
    pytest.param("quadrotor_hover_mpc", "cortex-m4", BOARD, [(40, 0.5), (20, -0.75)], marks=pytest.mark.matrix),
]


def artifact(name: str):
    logging.disable(logging.WARNING)
    try:
        return from_dict(design(load_spec(EXAMPLES / f"{name}.toml")).artifact)
    finally:
        logging.disable(logging.NOTSET)


@pytest.fixture(scope="module")
def pendulum():
    a = artifact("pendulum_mpc")
    return a, replay_image(a, target="cortex-m4", board=BOARD)


def closed_loop(a, legs: list[tuple[int, float]]) -> tuple[np.ndarray, np.ndarray]:
    """The host C (the image bit for bit) around the design's sampled plant; each leg puts the plant ``offset`` off
    (the pendulum's cart; the quadrotor's x, y and z) and runs ``steps`` (the law keeps its state across legs: its
    warm start is then far off)."""
    law = law_of(a)
    plant, c, r = law.plant(a), law.native(a), law.r_op(a)
    Y = []
    for steps, offset in legs:
        x0 = np.zeros(a.n)
        x0[: 3 if a.n == 12 else 1] = offset
        plant.reset(x0)
        for _ in range(steps):
            Y.append(plant.outputs())
            plant.advance(c.step(Y[-1], r, np.zeros(0)).u)
    return np.array(Y), np.tile(r, (len(Y), 1))


def test_only_the_non_finite_tests_and_the_stopping_test_depend_on_the_numbers(pendulum):
    """Every conditional branch of gl_mpc_step and its callees in the M4F image: the iteration's three passes have
    none the numbers decide (the box projections are selects), the step's are its non-finite tests (to refuse) and
    solve's stopping test."""
    _, elf = pendulum
    arg = branch_argument(elf)
    assert arg.holds, arg.violations
    assert {"gl_mpc_step", "solve", "backward", "forward", "slacks", "refuse"} <= set(arg.analysis.functions)
    for part in ("backward", "forward", "slacks"):
        assert arg.analysis.data_branches(part) == [], part
    assert len(arg.stop_tests) == 1 and arg.refuse_tests


@pytest.mark.parametrize("name,target,board,legs", CASES)
def test_the_bound_at_the_cap_covers_every_step_and_no_input_breaks_it(name, target, board, legs):
    """A closed loop from 1 m and then -1.5 m (capped steps, steps that stop early, both boxes and the inside hit) plus
    a NaN in each sample and reference element fits fixed part + iterations x one iteration exactly, with one
    iteration the three passes' counts (the same on every call) plus solve's loop body; the bound it gives is at least
    every count of a second run of extreme, alternating and random samples and references (every stage's box active,
    warm starts far off). The branch argument holds on the image."""
    a = artifact(name)
    elf = replay_image(a, target=target, board=board)
    assert branch_argument(elf).holds
    cap = a.mpc.max_iter
    Y, R = closed_loop(a, legs)
    Yn, Rn = refuse_samples(a.p, a.q, Y[-1], R[-1])
    Y, R = np.vstack([Y, Yn]), np.vstack([R, Rn])
    m = measure(a, elf, board=board, Y=Y, R=R)
    per_iteration = iteration_instructions(a, elf, board=board, Y=Y, R=R)  # NotProved if a pass's count varies
    bound = bound_of(m, cap, per_iteration)  # NotProved unless every count fits its path's formula
    assert m.capped.any() and m.refused.sum() == a.p + a.q
    assert bound.measured_max <= bound.bound
    if target == "cortex-m4":
        assert bound.bound <= {"pendulum_mpc": 50_000, "quadrotor_hover_mpc": 168_000}[name], "the issue's targets"
    if name == "pendulum_mpc":  # it stops at several counts: each fits the same fixed part (a check of I)
        assert len(set(m.iterations[~m.capped & ~m.refused].tolist())) >= 3
        zu = m.state[:, a.n + a.q : a.n + a.q + a.mpc.horizon * a.m]  # every stage's input slack
        lo, hi = np.float32(a.mpc.lo_u[0]), np.float32(a.mpc.hi_u[0])
        assert (zu == lo).any() and (zu == hi).any() and ((zu > lo) & (zu < hi)).any(), "below, above and inside"

    rng = np.random.default_rng(32)
    big = np.array([1e3, -1e3, 1e6, -1e6, 30.0, -30.0, 1e-30])
    Ya = np.vstack([
        np.outer(np.tile([1.0, -1.0], 10), big[:1].repeat(a.p)),  # alternating far off: warm starts on the wrong side
        rng.choice(big, size=(20, a.p)),
        rng.uniform(-50, 50, size=(20, a.p)),
    ])  # fmt: skip
    Ra = np.vstack([np.zeros((20, a.q)), rng.choice(big, size=(20, a.q)), rng.uniform(-50, 50, size=(20, a.q))])
    worst = measure(a, elf, board=board, Y=Ya, R=Ra)
    assert worst.capped.any()
    assert worst.counts.max() <= bound.bound, (int(worst.counts.max()), bound)


@pytest.mark.slow(cpu=4)
def test_each_soft_float_routine_has_a_bounded_path():
    """On the M0 the multiply-adds and float compares are calls whose paths depend on their operands: the hard-float
    cores' branch argument names them and does not hold there (the M0's bound is argued by soft_step_bound). Each of
    those routines (gl_fmaf, libgcc's add, subtract, multiply and compares, and what they call) has a loop-free graph,
    so its dearest call is bounded (gainlink.firmware.paths); QEMU's count of every call the step's own code makes
    over two steps (one 1 m off, one -1000 off: special operands, cancellations, boxes active) stays within it.
    __clzsi2, read by hand: 21 instructions with no branch taken, each of its three taken ``bcc`` skips two, so
    every call counts 15 to 21."""
    a = artifact("pendulum_mpc")
    elf = replay_image(a, target="cortex-m0", board="microbit")
    arg = branch_argument(elf)
    assert not arg.holds
    assert any("soft-float" in v and "gl_fmaf" in v for v in arg.violations), arg.violations
    bounds = Bounds(disassemble(elf))
    routines = {s.split(" calls ")[1] for s in arg.analysis.soft_float}
    assert {"gl_fmaf", "__aeabi_fadd", "__aeabi_fmul", "__aeabi_fcmplt"} <= routines
    for name in routines:
        assert bounds(name) > 0, name  # Unbounded if its graph had a cycle
    Y = np.array([[1.0] * a.p, [-1e3] * a.p])
    R = np.tile(law_of(a).r_op(a), (2, 1))
    # the calls the step's own code makes (the start-up checks call the compares with interrupts unmasked, and a
    # handler that runs during such a call is counted in it: 43 for a compare bounded by 42, at random)
    own = ("gl_mpc_step", "solve", "backward", "forward", "slacks", "refuse")
    direct = sorted({s.split(" calls ")[1] for s in arg.analysis.soft_float if s.split(" calls ")[0] in own})
    assert {"gl_fmaf", "__aeabi_fadd", "__aeabi_fmul", "__aeabi_fcmplt"} <= set(direct)
    for name, callers in (*((f, own) for f in direct), ("__clzsi2", ("gl_fmaf",))):
        cost = count_calls(elf, a, symbol=name, Y=Y, R=R, board="microbit", each=True, callers=callers)
        assert cost.calls > 0 and cost.dearest <= bounds(name), (name, cost.dearest, bounds(name))
        if name == "__clzsi2":
            assert bounds(name) == 21 and set(cost.each) <= {15, 17, 19, 21}


@pytest.mark.slow(cpu=7)
def test_the_m0_bound_at_the_cap_covers_every_step_and_no_input_breaks_it():
    """The M0's bound at the cap (gainlink.laws.mpc.cost.soft_step_bound) from three closed-loop steps from 1 m (one
    stops early, two reach the cap): one iteration at most solve's loop body plus each pass at its own instructions,
    its compare-decided detours and each soft-float call at its routine's dearest path; the fixed part likewise; a
    refused step at most the heaviest path to refuse. No step of a second run (alternating +-1e3, extreme values, all
    capped or stopping) and no refused step (a NaN or an infinity in each sample and reference element) passes it,
    and the measured steps are within it. It is loose (each float routine at its dearest path): under 2x the
    measured worst here."""
    a = artifact("pendulum_mpc")
    elf = replay_image(a, target="cortex-m0", board="microbit")
    Y, R = closed_loop(a, [(3, 1.0)])
    b = soft_step_bound(a, elf, board="microbit", Y=Y, R=R)
    assert b.measured_max <= b.bound < 2 * b.measured_max
    assert b.bound == max(b.refuse, b.fixed + b.cap * b.per_iteration)
    rng = np.random.default_rng(32)
    Ya = np.vstack([np.full((1, a.p), 1e3), np.full((1, a.p), -1e3), rng.choice([1e6, -1e6, 1e-30, 30.0], (2, a.p))])
    Ra = np.vstack([np.zeros((2, a.q)), rng.choice([1e6, -30.0, 1e-30], (2, a.q))])
    worst = measure(a, elf, board="microbit", Y=Ya, R=Ra)
    assert worst.capped.any() and worst.counts.max() <= b.bound
    Yn, Rn = refuse_samples(a.p, a.q, Y[-1], R[-1])
    Yi, Ri = Yn.copy(), Rn.copy()
    Yi[np.isnan(Yi)], Ri[np.isnan(Ri)] = np.inf, -np.inf
    refused = measure(a, elf, board="microbit", Y=np.vstack([Yn, Yi]), R=np.vstack([Rn, Ri]))
    assert refused.refused.all() and refused.counts.max() <= b.refuse


@pytest.mark.matrix
def test_the_m3_bound_at_the_cap_is_proved_and_no_input_breaks_it():
    """The M3's bound at the cap through prove(), as `pil run` and the bench report it (bound_block): proved, its
    premises printed (the frame's, and libgcc's normalisation loops bounded: the M3's __aeabi_fmul has two), the
    figure max(refused step, fixed + cap x one iteration). No step of a second run through QEMU's M3 (alternating
    +-1e3, random extremes with float32 subnormals 1e-40 that take fmul's normalisation loops, random within +-50)
    and no refused step (a NaN or an infinity in each sample and reference element) passes it. In the matrix: ~80 s
    for the pendulum, as the M0's (which stays in make test). The quadrotor's M3 image is not proved (its non-finite
    tests are a loop on the way to refuse: the refused step's heaviest path is not bounded)."""
    a = artifact("pendulum_mpc")
    elf = replay_image(a, target="cortex-m3", board="mps2-an385")
    block = bound_block(a, elf, board="mps2-an385", core="cortex-m3")
    assert block["proved"], block["covers"]
    assert {PREMISE, FRAME_PREMISE, SOFT_PREMISE, LOOP_PREMISE} <= set(block["premises"])
    assert len(normalisation_loops(disassemble(elf))) == 2
    bound = block["per_step"]
    assert bound == max(block["refused_step"], block["fixed"] + block["cap"] * block["per_iteration"])
    rng = np.random.default_rng(32)
    extremes = [1e6, -1e6, 1e-30, 1e-40, -1e-40, 30.0]
    Ya = np.vstack([np.full((1, a.p), 1e3), np.full((1, a.p), -1e3), rng.choice(extremes, (2, a.p)),
                    rng.uniform(-50, 50, (1, a.p))])  # fmt: skip
    Ra = np.vstack([np.zeros((2, a.q)), rng.choice(extremes, (2, a.q)), rng.uniform(-50, 50, (1, a.q))])
    worst = measure(a, elf, board="mps2-an385", Y=Ya, R=Ra)
    assert worst.capped.any() and worst.counts.max() <= bound, (int(worst.counts.max()), block)
    Y, R = closed_loop(a, [(1, 1.0)])
    Yn, Rn = refuse_samples(a.p, a.q, Y[-1], R[-1])
    Yi, Ri = Yn.copy(), Rn.copy()
    Yi[np.isnan(Yi)], Ri[np.isnan(Ri)] = np.inf, -np.inf
    refused = measure(a, elf, board="mps2-an385", Y=np.vstack([Yn, Yi]), R=np.vstack([Rn, Ri]))
    assert refused.refused.all() and refused.counts.max() <= block["refused_step"]


def test_the_dearest_path_of_hand_written_thumb():
    """Hand-written Thumb (the oracle is reading it): a diamond whose long side calls a 3-instruction leaf costs
    1 + 1 + (1 + 3) + 1 = 7 on that side against 4 on the other; a tail call adds the callee; a loop is refused."""
    leaf = ["200:\t2001      \tmovs\tr0, #1", "202:\t3001      \tadds\tr0, #1", "204:\t4770      \tbx\tlr"]
    f = [
        "100:\t2800      \tcmp\tr0, #0",
        "102:\td002      \tbeq.n\t10a <f+0xa>",
        "104:\tf000 f87c \tbl\t200 <leaf>",
        "108:\t4770      \tbx\tlr",
        "10a:\t2000      \tmovs\tr0, #0",
        "10c:\t4770      \tbx\tlr",
    ]
    g = ["300:\t2000      \tmovs\tr0, #0", "302:\te77d      \tb.n\t200 <leaf>"]
    loop = ["400:\t3801      \tsubs\tr0, #1", "402:\td1fd      \tbne.n\t400 <loop>", "404:\t4770      \tbx\tlr"]
    text = "".join(
        f"{base:08x} <{name}>:\n" + "\n".join(f"     {x}" for x in body) + "\n"
        for name, base, body in (("f", 0x100, f), ("leaf", 0x200, leaf), ("g", 0x300, g), ("loop", 0x400, loop))
    )
    bounds = Bounds(parse(text))
    assert bounds("leaf") == 3 and bounds("f") == 1 + 1 + (1 + 3) + 1 and bounds("g") == 1 + (1 + 3)
    with pytest.raises(Unbounded, match="loop"):
        bounds("loop")


def test_the_dearest_path_through_an_alias_a_fall_through_and_a_bounded_loop():
    """Hand-written Thumb-2 in the shapes of the M3's libgcc (the oracle is reading it): a call of a symbol objdump
    does not label (``__aeabi_fadd`` is ``__addsf3``'s address) costs the function at that address; a routine whose
    last instruction runs on into the next one (``__aeabi_fsub``'s ``eor`` into ``__addsf3``) costs 1 + that one; an
    ``ldr.w pc, [sp], #8`` is a return; libgcc's normalisation loop (``ittt eq; lsleq; tsteq #0x800000; subeq;
    beq``) is recognised and goes back at most 22 times: 1 + 5 + 22 x 5 + 1 = 117, and a loop shifting by two is
    not recognised (Unbounded)."""
    add = ["600:\t1840      \tadds\tr0, r0, r1", "602:\t4770      \tbx\tlr"]
    sub = ["5fc:\tf081 4100 \teor.w\tr1, r1, #2147483648"]
    cmp = ["700:\tf84d ed08 \tstr.w\tlr, [sp, #-8]!", "704:\tf7ff ff7c \tbl\t600 <__aeabi_fadd>",
           "708:\tf85d fb08 \tldr.w\tpc, [sp], #8"]  # fmt: skip
    norm = [
        "800:\tf092 0f00 \tteq\tr2, #0",
        "804:\tbf02      \tittt\teq",
        "806:\t0040      \tlsleq\tr0, r0, #1",
        "808:\tf410 0f00 \ttsteq.w\tr0, #8388608\t@ 0x800000",
        "80c:\t3a01      \tsubeq\tr2, #1",
        "80e:\td0f9      \tbeq.n\t804 <__aeabi_fmul+0x4>",
        "810:\t4770      \tbx\tlr",
    ]
    text = "".join(
        f"{base:08x} <{name}>:\n" + "\n".join(f"     {x}" for x in body) + "\n"
        for name, base, body in (("__aeabi_fsub", 0x5FC, sub), ("__addsf3", 0x600, add), ("__aeabi_fcmpeq", 0x700, cmp),
                                 ("__aeabi_fmul", 0x800, norm))
    )  # fmt: skip
    funcs = parse(text)
    bounds = routine_bounds(funcs)
    assert bounds("__addsf3") == 2 and bounds("__aeabi_fadd") == 2
    assert bounds("__aeabi_fsub") == 1 + 2
    assert bounds("__aeabi_fcmpeq") == 1 + (1 + 2) + 1
    assert normalisation_loops(funcs) == {("__aeabi_fmul", 0x80E): 22}
    assert bounds("__aeabi_fmul") == 1 + 5 + 22 * 5 + 1
    twice = parse(text.replace("lsleq\tr0, r0, #1", "lsleq\tr0, r0, #2"))
    assert normalisation_loops(twice) == {}
    with pytest.raises(Unbounded, match="loop"):
        routine_bounds(twice)("__aeabi_fmul")


def test_a_clamp_with_two_compares_is_a_detour():
    """Hand-written Thumb-2 in the shape of the M3 step's command clamp (the oracle is reading it): compare, then on
    either side a second compare and maybe a move, all four paths meeting at the ``nop`` with two calls of the compare
    each: paths of 5, 7 (0x112's side, falling through then taken), 7 and 10 own instructions, so one execution runs
    at most 5 more than another. A side that calls once more than the other is not a detour."""
    clamp = [
        "bl\t200 <__aeabi_fcmplt>",  # 100
        "cmp\tr0, #0",
        "beq.n\t118 <f+0x18>",  # 104
        "mov\tr0, r4",
        "ldr\tr1, [sp, #0]",
        "bl\t200 <__aeabi_fcmplt>",  # 10a
        "cmp\tr0, #0",
        "bne.n\t114 <f+0x14>",  # 10e
        "nop",  # 110: the meet
        "bx\tlr",
        "str\tr4, [sp, #0]",  # 114
        "b.n\t110 <f+0x10>",
        "ldr\tr3, [sp, #4]",  # 118
        "mov\tr0, r4",
        "str\tr3, [sp, #0]",
        "ldr\tr1, [sp, #0]",
        "bl\t200 <__aeabi_fcmplt>",  # 120
        "cmp\tr0, #0",
        "beq.n\t110 <f+0x10>",  # 126
        "b.n\t114 <f+0x14>",
    ]
    text = _function("f", 0x100, clamp) + _function("__aeabi_fcmplt", 0x200, ["bx\tlr"])
    funcs = parse(text)
    first = next(b for b in analyse_text(funcs, "f").branches if b.insn.address == 0x104)
    assert detour(funcs, "f", first) == ("__aeabi_fcmplt", 10 - 5)
    funcs = parse(text.replace("ldr\tr3, [sp, #4]", "bl\t200 <__aeabi_fcmplt>"))
    first = next(b for b in analyse_text(funcs, "f").branches if b.insn.address == 0x104)
    with pytest.raises(NotProved, match="different calls"):
        detour(funcs, "f", first)


def test_the_analysis_tells_the_numbers_branches_from_the_paths_fixed_ones():
    """Hand-written Thumb-2 (the oracle is reading it): a clamp as a branch on a float compare is data, as an IT block
    it is no branch; a flag set by a predicated move pair is, on each edge of a branch on the same condition, the
    constant that edge implies (clean: decided by that branch); a word loaded and tested bit by bit is data; a
    loaded address stepped to an end is not."""
    lines = [
        "100:\teef4 7ac5 \tvcmpe.f32\ts15, s10",
        "104:\teef1 fa10 \tvmrs\tAPSR_nzcv, fpscr",
        "108:\td501      \tbpl.n\t10e <f+0xe>",
        "10a:\teef0 7a45 \tvmov.f32\ts15, s10",
        "10e:\teef4 7a65 \tvcmp.f32\ts15, s11",
        "112:\teef1 fa10 \tvmrs\tAPSR_nzcv, fpscr",
        "116:\tbfc8      \tit\tgt",
        "118:\teef0 7a65 \tvmovgt.f32\ts15, s11",
        "11c:\tbf8c      \tite\thi",
        "11e:\t2701      \tmovhi\tr7, #1",
        "120:\t2700      \tmovls\tr7, #0",
        "122:\td802      \tbhi.n\t12a <f+0x2a>",
        "124:\t2f00      \tcmp\tr7, #0",
        "126:\td1eb      \tbne.n\t100 <f>",
        "128:\tbf00      \tnop",
        "12a:\t680b      \tldr\tr3, [r1, #0]",
        "12c:\tf023 4300 \tbic.w\tr3, r3, #2147483648",
        "130:\t2b00      \tcmp\tr3, #0",
        "132:\td0e5      \tbeq.n\t100 <f>",
        "134:\t6802      \tldr\tr2, [r0, #0]",
        "136:\t3204      \tadds\tr2, #4",
        "138:\t428a      \tcmp\tr2, r1",
        "13a:\td1fb      \tbne.n\t134 <f+0x34>",
        "13c:\t4770      \tbx\tlr",
    ]
    a = analyse_text(parse("00000100 <f>:\n" + "\n".join(f"     {x}" for x in lines)), "f")
    by = {b.insn.address: b for b in a.branches}
    assert sorted(by) == [0x108, 0x122, 0x126, 0x132, 0x13A], "the IT block is no branch"
    assert by[0x108].origins == {"float"} and by[0x122].origins == {"float"}
    assert not by[0x126].data, "r7 is 0 on the fall-through of bhi, whatever the compare said"
    assert by[0x132].data and "bits" in by[0x132].origins
    assert not by[0x13A].data, "an address loaded and stepped to an end"


def _function(name: str, base: int, lines: list[str]) -> str:
    """objdump -d text of a hand-written function: ``lines`` are "mnemonic<TAB>operands", two bytes apart."""
    body = "\n".join(f"     {base + 2 * k:x}:\tbf00      \t{line}" for k, line in enumerate(lines))
    return f"{base:08x} <{name}>:\n{body}\n"


def _branches(lines: list[str]) -> dict[int, object]:
    """The conditional branches of ``f`` (at 0x100, calling ``g`` at 0x200), by the index of their line."""
    text = _function("f", 0x100, lines) + _function("g", 0x200, ["bx\tlr"])
    a = analyse_text(parse(text), "f")
    return {(b.insn.address - 0x100) // 2: b for b in a.branches}


def test_a_counter_spilled_to_the_stack_and_reloaded_is_fixed():
    """Hand-written Thumb-2 (the oracle is reading it): a 0/1 toggle kept in [sp, #4] across a call (which clobbers
    r0-r3) and reloaded, flipped with an eor, stored back, tested: it starts at the immediate 0 and only ever
    holds what the code put there, so the loop's branch is fixed. Without stack-slot tracking the reload is a
    loaded word and the eor made it a float's bits (the M3's backward pass was refused on this)."""
    by = _branches([
        "push\t{r4, lr}",
        "sub\tsp, #8",
        "movs\tr3, #0",
        "str\tr3, [sp, #4]",
        "bl\t200 <g>",
        "ldr\tr3, [sp, #4]",
        "eor.w\tr3, r3, #1",
        "str\tr3, [sp, #4]",
        "cmp\tr3, #0",
        "bne.n\t108 <f+0x8>",
        "add\tsp, #8",
        "pop\t{r4, pc}",
    ])  # fmt: skip
    assert not by[9].data, by[9].origins


def test_a_counter_spilled_through_a_frame_pointer_is_fixed():
    """The same toggle kept through a frame pointer (r7 = sp after the push and the sub) at [r7, #4]: fixed. The
    frame pointer's offset follows ``add r7, sp, #0``; the slot is the same one [sp, #4] names."""
    by = _branches([
        "push\t{r7, lr}",
        "sub\tsp, #8",
        "add\tr7, sp, #0",
        "movs\tr3, #0",
        "str\tr3, [r7, #4]",
        "bl\t200 <g>",
        "ldr\tr3, [sp, #4]",
        "eor.w\tr3, r3, #1",
        "str\tr3, [r7, #4]",
        "cmp\tr3, #0",
        "bne.n\t10a <f+0xa>",
        "add\tsp, #8",
        "pop\t{r7, pc}",
    ])  # fmt: skip
    assert not by[10].data, by[10].origins


def test_a_float_word_spilled_to_the_stack_is_data_when_reloaded():
    """A soft-float result (what g returned in r0) spilled to [sp, #4] across a second call and reloaded into r3,
    then tested against 0: the test is decided by g's result, data. Without stack-slot tracking the reload was a
    loaded word and the test was called fixed."""
    by = _branches([
        "push\t{r4, lr}",
        "sub\tsp, #8",
        "bl\t200 <g>",
        "str\tr0, [sp, #4]",
        "bl\t200 <g>",
        "ldr\tr3, [sp, #4]",
        "cmp\tr3, #0",
        "beq.n\t114 <f+0x14>",
        "movs\tr0, #1",
        "nop",
        "add\tsp, #8",
        "pop\t{r4, pc}",
    ])  # fmt: skip
    assert by[7].data and "ret:g" in by[7].origins


def test_a_slot_the_analysis_cannot_pin_is_data():
    """The slot [sp, #4] holds the immediate 0, then is overwritten through a pointer to it (``add r2, sp, #4``) with
    g's result: the reload is g's result, data. Its address passed to a call (g may write it), or sp moved by a
    register (no slot is pinned any more): the reload is unknown, data. Without stack-slot tracking each reload was
    a loaded word, fixed."""
    through_pointer = _branches([
        "push\t{r4, lr}",
        "sub\tsp, #8",
        "movs\tr3, #0",
        "str\tr3, [sp, #4]",
        "bl\t200 <g>",
        "add\tr2, sp, #4",
        "str\tr0, [r2, #0]",
        "ldr\tr3, [sp, #4]",
        "cmp\tr3, #0",
        "bne.n\t108 <f+0x8>",
        "add\tsp, #8",
        "pop\t{r4, pc}",
    ])  # fmt: skip
    assert through_pointer[9].data and "ret:g" in through_pointer[9].origins
    escaped = _branches([
        "push\t{r4, lr}",
        "sub\tsp, #8",
        "movs\tr3, #0",
        "str\tr3, [sp, #4]",
        "add\tr0, sp, #4",
        "bl\t200 <g>",
        "ldr\tr3, [sp, #4]",
        "cmp\tr3, #0",
        "bne.n\t108 <f+0x8>",
        "add\tsp, #8",
        "pop\t{r4, pc}",
    ])  # fmt: skip
    assert escaped[8].data, escaped[8].origins
    moved = _branches([
        "push\t{r4, lr}",
        "movs\tr3, #0",
        "str\tr3, [sp, #4]",
        "mov\tsp, r1",
        "ldr\tr3, [sp, #4]",
        "cmp\tr3, #0",
        "bne.n\t108 <f+0x8>",
        "pop\t{r4, pc}",
    ])  # fmt: skip
    assert moved[6].data, moved[6].origins
