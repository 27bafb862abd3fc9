"""Cost of one step of the MPC law (issue 32, "Cost is a certificate"): instructions per step in QEMU on the
Cortex-M0, M4F and M7, per iteration and per step at the cap, flash and RAM.

Designs: ``examples/pendulum_mpc.toml`` (5 states with the integrator, 1 input, horizon 20, cap 10) and
``examples/quadrotor_hover_mpc.toml`` (12 states, 4 inputs, horizon 10, cap 10). Samples: the host C closing the loop
around the design's own sampled plant from a start that drives the inputs into their boxes (the pendulum 1 m off its
reference, the quadrotor 0.5 m off in x, y and z), replayed through each image (the image is the host's bit for bit,
so every core sees the same trajectory and runs the same iterations).

What is counted (gainlink.firmware.cost's plugin, exact and deterministic): every call of ``gl_mpc_step`` (the
law's step, callees included: on the M0 the correctly rounded ``gl_fmaf`` of every multiply-add) and of the three
parts of an iteration, ``backward``, ``forward`` and ``slacks`` (functions of their own, ``noinline``). The cost of an
iteration is the sum of the three parts' dearest calls; the bound of a step is its fixed part (the step's instructions
outside the iterations, the dearest over the run: the step's total minus its iterations at their dearest cost is a
lower estimate, so the fixed part is taken as the dearest step minus the cap's iterations at their cheapest, an
upper estimate on this run) plus the cap times the iteration's cost. On an FPU core the passes have no data-dependent
branch but the slack step's clamps, so their counts vary by a few instructions; on the M0 ``gl_fmaf``'s paths depend on
the operands. Measured on this run, not proved for every input: the report says so. Instructions are not cycles (a
``vfma.f32`` takes 3 cycles on the M4F; flash wait states add more): times are not given here.

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
from gainlink.firmware.build import replay_image
from gainlink.firmware.cost import count_calls, count_step_instructions
from gainlink.firmware.size import size_report, symbol_sizes
from gainlink.firmware.targets import resolve_cortex_m
from gainlink.laws import design as design_spec
from gainlink.laws import law_of
from gainlink.laws.flags import CAPPED
from gainlink.shipping.artifact import from_dict
from gainlink.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
TARGETS = ("cortex-m0", "cortex-m4", "cortex-m7")
STEPS = {"cortex-m0": 3, "cortex-m4": 60, "cortex-m7": 60}  # the M0 runs ~4M instructions a step through gl_fmaf
PASSES = ("backward", "forward", "slacks")
TARGET_INSTRUCTIONS = {"pendulum_mpc": 50_000, "quadrotor_hover_mpc": 168_000}
RAM_TARGET = {"quadrotor_hover_mpc": 16 * 1024}


def closed_loop_samples(a, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The host C around the design's sampled plant from a start that saturates the inputs: samples and refs."""
    law = law_of(a)
    plant = law.plant(a)
    x0 = np.zeros(a.n)
    x0[: 3 if a.n == 12 else 1] = 0.5 if a.n == 12 else 1.0  # quadrotor: x, y, z; pendulum: the cart
    plant.reset(x0)
    c = law.native(a)
    Y, R = np.zeros((steps, a.p)), np.tile(law.r_op(a), (steps, 1))
    for k in range(steps):
        Y[k] = plant.outputs()
        plant.advance(c.step(Y[k], R[k], np.zeros(0)).u)
    return Y, R


def measure(a, target: str) -> dict:
    """Counts and sizes of ``a``'s replay image on ``target`` (module docstring)."""
    platform = resolve_cortex_m(target, None)
    board = platform.board.name
    try:
        elf = replay_image(a, target=platform.target.name, board=board)
    except ToolchainError as exc:  # the micro:bit's 16 KiB of RAM: the quadrotor's replay image does not fit
        return {"target": target, "board": board, "built": False, "why": str(exc)[-160:]}
    Y, R = closed_loop_samples(a, STEPS[target])
    host = law_of(a).replay(a, "native", Y, R)  # the image's run bit for bit (tests/test_mpc.py)
    iters = host.iterations
    step = count_step_instructions(elf, a, Y=Y, R=R, board=board)
    parts = {p: count_calls(elf, a, symbol=p, Y=Y, R=R, board=board) for p in PASSES}
    per_iter_worst = sum(parts[p].dearest for p in PASSES)
    per_iter_cheap = sum(parts[p].cheapest for p in PASSES)
    fixed = step.dearest - int(iters.max()) * per_iter_cheap
    cap = a.mpc.max_iter
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
        "bound_per_step_at_cap": fixed + cap * per_iter_worst,
        "bound_scope": "measured on this run (fixed part and passes at their dearest), not proved for any input",
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
    Y, R = closed_loop_samples(a, STEPS["cortex-m4"])
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
