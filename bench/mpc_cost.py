"""Cost of one step of the MPC law (issue 32, "Cost is a certificate"): instructions per step in QEMU on the
Cortex-M0, M3, M4F, M7, M33 and M55, per iteration and per step at the cap, flash and RAM.

Designs: ``examples/pendulum_mpc.toml`` (5 states with the integrator, 1 input, horizon 20, cap 10) and
``examples/quadrotor_hover_mpc.toml`` (12 states, 4 inputs, horizon 10, cap 10). Samples: the host C closing the loop
around the design's own sampled plant from a start that drives the inputs into their boxes (the pendulum 1 m off its
reference, the quadrotor 0.5 m off in x, y and z), replayed through each image (the image is the host's bit for bit,
so every core sees the same trajectory and runs the same iterations).

What is counted (gainlink.firmware.cost's plugin, exact and deterministic): every call of ``gl_mpc_step`` (the
law's step, callees included: on the M0 the correctly rounded ``gl_fmaf`` of every multiply-add), each call's count
apart, and of the three parts of an iteration, ``backward``, ``forward`` and ``slacks`` (functions of their own,
``noinline``).

The bound at the cap (gainlink.laws.mpc.cost) is **proved** on the hard-float cores (M4F, M7, M33, M55) for the image
measured (that core, the compiler and flags printed, the tables' dimensions: any numbers in them, any samples, any
warm start): the disassembly of that image shows that the law's numbers decide only the non-finite tests and the
solver's stopping test (``branch_argument``: every other conditional branch of the step and its callees is fixed),
so a step's count is a refuse path's, or F_stop + it x I, or F_cap + cap x I, with I the three passes' counts (each
the same on every call, checked) plus solve's own loop body (counted on the disassembly); the run (a closed loop from
1 m, then -1.5 m, then a NaN in each sample and reference element) must fit those formulas exactly, and gives F_stop,
F_cap and the bound. Then a second run tries to break it (extreme, alternating and random samples and references)
and its worst count is printed beside. On the M0 and the M3 (soft float: ``gl_fmaf``'s and the compare routines'
paths depend on their operands) the bound is proved another way (``soft_step_bound``): every float routine the step
calls is charged at its longest path on the disassembly, loop-free but for libgcc's normalisation of a subnormal
operand in the M3's ``__aeabi_fmul`` (at most 22 times back: a premise printed with the bound;
``soft_float_routines`` prints each bound beside the dearest call measured), the compare-decided clamps are detours
charged at their longest path, and the counts of the first ``SOFT_STEPS`` closed-loop steps give each pass's and the
fixed part's own instructions; a refused step is bounded by the heaviest path to ``refuse``. It is loose (each routine
at its dearest path), and six adversarial steps are measured beside it. The quadrotor's M3 image is not proved (its
non-finite tests are a loop on the way to ``refuse``): its figure is then measured, and says so; the micro:bit's 16 KiB
of RAM does not hold the quadrotor's M0 image.
Instructions are not cycles (a ``vfma.f32`` takes 3 cycles on the M4F; flash wait states add more): times are not
given here.

Targets (issue 32, M4F, worst case): pendulum <= 50,000 instructions per step; quadrotor <= 168,000, and the law's
state, workspace and both gain banks <= 16 KiB of RAM (``law_ram_with_both_banks_bytes``: the image's
``gl_law_t`` and twice the tables, the compiled set and a staged one, as if both were in RAM; the replay image's own
stream buffers are not the law's and are reported apart).

    .venv/bin/python bench/mpc_cost.py > bench/results/mpc_cost.json
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

import numpy as np
from gainlink.errors import ToolchainError
from gainlink.firmware.branches import SOFT_FLOAT, disassemble
from gainlink.firmware.build import replay_image
from gainlink.firmware.cost import count_calls, count_step_instructions
from gainlink.firmware.paths import Unbounded
from gainlink.firmware.size import size_report, symbol_sizes
from gainlink.firmware.targets import resolve_cortex_m
from gainlink.laws import design as design_spec
from gainlink.laws import law_of
from gainlink.laws.flags import CAPPED
from gainlink.laws.mpc.cost import (
    LEGS,
    SOFT_STEPS,
    NotProved,
    branch_argument,
    closed_loop_samples,
    premises,
    prove,
    routine_bounds,
)
from gainlink.laws.mpc.cost import measure as measure_steps
from gainlink.shipping.artifact import from_dict
from gainlink.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
TARGETS = ("cortex-m0", "cortex-m3", "cortex-m4", "cortex-m7", "cortex-m33", "cortex-m55")
SOFT_CORES = ("cortex-m0", "cortex-m3")  # ~1.4-3M instructions a step through gl_fmaf: the first SOFT_STEPS only
PASSES = ("backward", "forward", "slacks")
TARGET_INSTRUCTIONS = {"pendulum_mpc": 50_000, "quadrotor_hover_mpc": 168_000}
RAM_TARGET = {"quadrotor_hover_mpc": 16 * 1024}


def adversarial_samples(a, steps: int = 60, seed: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Samples and references chosen to break the bound: alternating far off (the warm start on the wrong side, every
    stage's box active), random extremes (NaN-free, 1e-30 to 1e6 of either sign), random within +-50."""
    rng = np.random.default_rng(seed)
    big = np.array([1e3, -1e3, 1e6, -1e6, 30.0, -30.0, 1e-30])
    third = steps // 3
    Y = np.vstack([np.outer(np.tile([1.0, -1.0], third // 2), np.full(a.p, 1e3)),
                   rng.choice(big, size=(third, a.p)), rng.uniform(-50, 50, size=(third, a.p))])  # fmt: skip
    R = np.vstack([np.tile(law_of(a).r_op(a), (third, 1)), rng.choice(big, size=(third, a.q)),
                   rng.uniform(-50, 50, size=(third, a.q))])  # fmt: skip
    return Y, R


def compile_flags(elf: Path) -> str:
    """The flags the law's C was compiled with for ``elf`` (its CMake build's ninja file)."""
    text = (elf.parent / "build.ninja").read_text()
    at = text.index("gl_mpc.c.obj:")
    line = next(ln for ln in text[at:].splitlines() if ln.strip().startswith("FLAGS ="))
    return line.split("=", 1)[1].strip()


def soft_proved_bound(a, elf: Path, board: str, arg) -> dict:
    """The soft-float cores' bound at the cap (gainlink.laws.mpc.cost.prove: soft_step_bound on the first SOFT_STEPS
    steps of the closed loop), or why not; a short run of adversarial steps beside it."""
    try:
        b = prove(a, elf, board=board, arg=arg)
    except NotProved as exc:
        return {"proved": False, "why": str(exc)}
    Ya, Ra = adversarial_samples(a, steps=6)
    worst = measure_steps(a, elf, board=board, Y=Ya, R=Ra)
    return {"proved": True, "method": "soft float: each routine at its dearest path", **b.summary(),
            "bound_over_measured_worst": round(b.bound / b.measured_max, 2), "adversarial_steps": len(worst.counts),
            "adversarial_capped": int(worst.capped.sum()), "adversarial_worst": int(worst.counts.max()),
            "adversarial_within_bound": bool(worst.counts.max() <= b.bound)}  # fmt: skip


def proved_bound(a, elf: Path, board: str) -> dict:
    """The bound at the cap proved for ``elf`` (module docstring: gainlink.laws.mpc.cost.prove), or why not; the
    attempt to break it."""
    arg = branch_argument(elf)
    out = {"argument": arg.summary(), "compile_flags": compile_flags(elf)}
    if not arg.holds and arg.analysis.soft_float:
        return {**out, **soft_proved_bound(a, elf, board, arg), "premises": premises(elf, soft=True)}
    if not arg.holds:
        return {**out, "proved": False}
    try:
        bound = prove(a, elf, board=board, arg=arg)
    except NotProved as exc:
        return {**out, "proved": False, "why": str(exc)}
    run_steps = sum(steps for steps, _ in LEGS) + a.p + a.q
    Ya, Ra = adversarial_samples(a)
    worst = measure_steps(a, elf, board=board, Y=Ya, R=Ra)
    return {**out, "proved": True, **bound.summary(), "premises": premises(elf, soft=False), "run_steps": run_steps,
            "adversarial_steps": len(worst.counts), "adversarial_capped": int(worst.capped.sum()),
            "adversarial_worst": int(worst.counts.max()),
            "adversarial_within_bound": bool(worst.counts.max() <= bound.bound)}  # fmt: skip


def soft_float_routines(a, elf: Path, board: str, Y, R, proof: dict) -> dict:
    """Each soft-float routine the step calls: its dearest call proved on the disassembly (gainlink.firmware.paths: a
    loop-free graph's longest path, callees included) beside the dearest call the step made on this run."""
    funcs = disassemble(elf)
    bounds = routine_bounds(funcs)
    # the step's own code: the start-up checks call the compares with interrupts unmasked (a handler would be counted)
    step = tuple(f for f in proof["argument"]["functions"] if not SOFT_FLOAT.match(f) and f != "__clzsi2")
    out = {}
    calls = [v.split(" calls ") for v in proof["argument"]["violations"] if " calls " in v]
    called = {c[1].split(" ")[0] for c in calls if c[0].split(" ")[-1] in step}
    for name in sorted(called):
        try:
            bound: int | str = bounds(name)
        except Unbounded as exc:
            bound = f"unbounded: {exc}"
        cost = count_calls(elf, a, symbol=name, Y=Y, R=R, board=board, callers=step)
        out[name] = {"bound_per_call": bound, "measured_worst_per_call": cost.dearest, "calls": cost.calls}
    return out


def measure(a, target: str) -> dict:
    """Counts, sizes and the bound of ``a``'s replay image on ``target`` (module docstring)."""
    platform = resolve_cortex_m(target, None)
    board = platform.board.name
    try:
        elf = replay_image(a, target=platform.target.name, board=board)
    except ToolchainError as exc:  # the micro:bit's 16 KiB of RAM: the quadrotor's replay image does not fit
        return {"target": target, "board": board, "built": False, "why": str(exc)[-160:]}
    Y, R = closed_loop_samples(a)
    if target in SOFT_CORES:
        Y, R = Y[:SOFT_STEPS], R[:SOFT_STEPS]
    host = law_of(a).replay(a, "native", Y, R)  # the image's run bit for bit (tests/test_mpc.py)
    iters = host.iterations
    step = count_step_instructions(elf, a, Y=Y, R=R, board=board)
    parts = {p: count_calls(elf, a, symbol=p, Y=Y, R=R, board=board) for p in PASSES}
    per_iter_worst = sum(parts[p].dearest for p in PASSES)
    per_iter_cheap = sum(parts[p].cheapest for p in PASSES)
    cap = a.mpc.max_iter
    proof = proved_bound(a, elf, board)
    if proof["proved"] and "method" in proof:
        bound = proof["bound"]
        scope = (f"proved for every input on this image ({target}, {proof['compile_flags']}; horizon "
                 f"{a.mpc.horizon}, {a.mpc.nx} states, {a.m} inputs, {a.mpc.nc} box rows, cap {cap}): every "
                 "soft-float routine the step calls is loop-free and charged at its longest path, the passes' and the "
                 "step's compare-decided branches are detours charged at their longer side, a refused step at the "
                 "heaviest path to refuse; loose (each routine at its dearest path); premises: "
                 + "; ".join(proof["premises"]))  # fmt: skip
    elif proof["proved"]:
        bound = proof["bound"]
        scope = (f"proved for every input on this image ({target}, {proof['compile_flags']}; horizon "
                 f"{a.mpc.horizon}, {a.mpc.nx} states, {a.m} inputs, {a.mpc.nc} box rows, cap {cap}): the numbers "
                 "decide only the non-finite tests and the stopping test (the disassembly), and the run fits fixed "
                 "part + iterations x one iteration exactly; premises: " + "; ".join(proof["premises"]))  # fmt: skip
    else:
        bound = step.dearest - int(iters.max()) * per_iter_cheap + cap * per_iter_worst
        why = "; ".join(proof["argument"]["violations"][:2]) + (f" ({proof['why']})" if "why" in proof else "")
        scope = f"measured on this run (fixed part and passes at their dearest), not proved: {why}"
    if target in SOFT_CORES and proof["proved"]:  # the routines' bounds the proof charged, beside their dearest calls
        proof["soft_float_routines"] = soft_float_routines(a, elf, board, Y, R, proof)
    size = size_report(elf, board=board)
    syms = symbol_sizes(elf, ("gl_mpc_default", "gl_mpc_step", "law"))
    tables = syms.get("gl_mpc_default", {}).get("size", 0)
    state = syms.get("law", {}).get("size", 0)  # the image's gl_law_t: state, warm start and workspace
    return {
        "target": target,
        "board": board,
        "steps": step.calls,
        "iterations_mean": round(float(iters.mean()), 2),
        "iterations_max": int(iters.max()),
        "capped_steps": int(np.count_nonzero(host.flags & CAPPED)),  # the cap stopped it (not converged at it)
        "instructions_per_step_mean": round(step.per_step, 1),
        "instructions_per_step_worst": step.dearest,
        "instructions_per_step_cheapest": step.cheapest,
        "instructions_per_iteration_worst": per_iter_worst,
        "instructions_per_iteration_parts_worst": {p: parts[p].dearest for p in PASSES},
        "instructions_per_iteration_parts_constant": all(parts[p].dearest == parts[p].cheapest for p in PASSES),
        "bound_per_step_at_cap": bound,
        "bound_proved": proof["proved"],
        "bound_scope": scope,
        "proof": proof,
        "step_code_bytes": syms.get("gl_mpc_step", {}).get("size", 0),
        "tables_bytes": tables,
        "law_state_and_workspace_bytes": state,
        "law_ram_with_both_banks_bytes": state + 2 * tables,
        "image_flash_bytes": size["flash_bytes"],
        "image_ram_bytes_without_stack": size["ram_bytes_without_stack"],
    }


def lq_baseline(name: str, a) -> dict:
    """The baseline measured in the same run: the observer-based law of the same spec (``method = "lqr"``, the law
    the MPC reduces to with no constraint active) on the M4F, its step's instructions on the same samples."""
    import tomllib

    from gainlink.spec import parse_spec

    data = tomllib.loads((ROOT / "examples" / f"{name}.toml").read_text())
    data["controller"]["method"] = "lqr"
    data.pop("mpc")
    lq = from_dict(design_spec(parse_spec(data)).artifact)
    Y, R = closed_loop_samples(a)
    elf = replay_image(lq, target="cortex-m4", board="mps2-an386")
    step = count_step_instructions(elf, lq, Y=Y, R=R, board="mps2-an386")
    return {"law": "lq/float32 (method = lqr, the same weights)", "instructions_per_step_mean": round(step.per_step, 1),
            "instructions_per_step_worst": step.dearest}  # fmt: skip


def main() -> None:
    logging.basicConfig(level=logging.WARNING)
    out = {"benchmark": "mpc_cost", "note": "instructions, not cycles (vfma.f32 takes 3 cycles on the M4F)",
           "designs": []}  # fmt: skip
    for name in TARGET_INSTRUCTIONS:
        a = from_dict(design_spec(load_spec(ROOT / "examples" / f"{name}.toml")).artifact)
        b = a.mpc
        row = {"design": name, "nx": b.nx, "m": a.m, "horizon": b.horizon, "cap": b.max_iter, "box_rows": b.nc,
               "macs_per_iteration": b.horizon * (2 * b.nx * b.nx + 4 * b.nx * a.m + a.m * a.m),
               "targets": [measure(a, t) for t in TARGETS]}  # fmt: skip
        m4 = next(r for r in row["targets"] if r["target"] == "cortex-m4")
        row["target_m4f_instructions_per_step_worst"] = TARGET_INSTRUCTIONS[name]
        row["baseline_m4f"] = lq_baseline(name, a)
        row["ratio_to_baseline_worst"] = round(
            m4["instructions_per_step_worst"] / row["baseline_m4f"]["instructions_per_step_worst"], 1
        )
        row["m4f_worst_within_target"] = m4["instructions_per_step_worst"] <= TARGET_INSTRUCTIONS[name]
        row["m4f_bound_within_target"] = m4["bound_per_step_at_cap"] <= TARGET_INSTRUCTIONS[name]
        if name in RAM_TARGET:
            row["m4f_law_ram_with_both_banks_within_16KiB"] = m4["law_ram_with_both_banks_bytes"] <= RAM_TARGET[name]
        out["designs"].append(row)
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
