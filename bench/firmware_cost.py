"""Cost of one control step on the Cortex-M cores: instructions per step in QEMU, flash and RAM.

Prints JSON. Instructions are counted from each call of gl_loop_step to its return, callees included
(gainlink.firmware.cost), so the soft-float routines of the M0 and M3 are in the count.

- ``results`` (Cortex-M4F, mps2-an386): the pendulum example (Kalman, integral action on position,
  back-calculation) and random designs with n = 4, 8, 12, 16 (m = p = 2, one integrator). For each:
  instructions per step of the shipped build (generated unrolled step) and of the generic-loop build
  measured in the same run (the baseline; `speedup` is their ratio), the multiply-accumulates of the law
  as docs/design.md writes it ("The control law"), the ratio instructions / MACs, and flash/RAM from the size
  report. Targets:
  pendulum <= 100 instructions per step; <= 2x the MAC count at n = 12.
- ``per_target``: the pendulum on every core (float32; ``numeric`` names the law, for the fixed-point
  columns to come): instructions per step (mean, dearest step, and the part inside gl_loop_step's own
  symbol), flash and RAM. On the soft-float cores, the cost of the correctly rounded multiply-add
  (gl_fmaf, instructions per call) and the same step with the two baselines built in the same run:
  newlib's fmaf (rounded twice, not bit for bit with the host) and a plain multiply-then-add.

    .venv/bin/python bench/firmware_cost.py
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

from gainlink.firmware.build import build
from gainlink.firmware.cost import count_calls, count_step_instructions, implemented_macs, law_macs
from gainlink.firmware.size import size_report
from gainlink.firmware.targets import CORTEX_M_TARGETS, TARGETS
from gainlink.laws.lq.golden import example_cases, random_case
from gainlink.proof.reference import ReferenceLoop

ROOT = Path(__file__).resolve().parents[1]
STEPS = 2000


def measure(label: str, artifact, Y, R) -> dict:
    shipped = build(artifact, target="cortex-m4").files["elf"]
    generic = build(artifact, target="cortex-m4", options={"GL_STEP_UNROLLED": "OFF"}).files["elf"]
    cost = count_step_instructions(shipped, artifact, Y=Y, R=R)
    base = count_step_instructions(generic, artifact, Y=Y, R=R)
    size = size_report(shipped, board="mps2-an386")
    macs = law_macs(artifact)
    sat = ReferenceLoop(artifact).run(Y, R).saturated.any(axis=1).mean()
    return {
        "design": label,
        "n": artifact.n,
        "m": artifact.m,
        "p": artifact.p,
        "q": artifact.q,
        "observer_form": artifact.observer_form,
        "anti_windup": artifact.anti_windup,
        "steps": cost.calls,
        "saturated_fraction": round(float(sat), 3),
        "instructions_per_step": round(cost.per_step, 2),
        "baseline_generic_loop_instructions_per_step": round(base.per_step, 2),
        "speedup_vs_generic": round(base.per_step / cost.per_step, 3),
        "law_macs": macs,
        "implemented_macs": implemented_macs(artifact),
        "instructions_per_law_mac": round(cost.per_step / macs, 3),
        "flash_bytes": size["flash_bytes"],
        "ram_bytes_without_stack": size["ram_bytes_without_stack"],
        "step_code_bytes": size["symbols"]["gl_loop_step"]["size"],
    }


def measure_target(target: str, artifact, Y, R) -> dict:
    """The pendulum's float32 step on ``target`` (its default board)."""
    board = TARGETS[target].default_board
    elf = build(artifact, target=target).files["elf"]
    cost = count_step_instructions(elf, artifact, Y=Y, R=R, board=board)
    size = size_report(elf, board=board)
    row = {
        "target": target,
        "board": board,
        "numeric": "float32",
        "fpu": TARGETS[target].hardware_fma,
        "instructions_per_step": round(cost.per_step, 1),
        "dearest_step_instructions": cost.dearest,
        "own_instructions_per_step": round(cost.own_per_step, 1),
        "flash_bytes": size["flash_bytes"],
        "ram_bytes_without_stack": size["ram_bytes_without_stack"],
        "ram_bytes": size["ram_bytes"],
    }
    if not TARGETS[target].hardware_fma:
        fma = count_calls(elf, artifact, symbol="gl_fmaf", Y=Y, R=R, board=board)
        row["gl_fmaf_calls_per_step"] = round(fma.calls / cost.calls, 2)
        row["gl_fmaf_instructions_per_call"] = round(fma.per_step, 1)
        for baseline in ("newlib", "plain"):
            other = build(artifact, target=target, options={"GL_SOFT_FMA": baseline}).files["elf"]
            per_step = count_step_instructions(other, artifact, Y=Y, R=R, board=board).per_step
            row[f"baseline_{baseline}_fma_instructions_per_step"] = round(per_step, 1)
            row[f"ratio_to_{baseline}_fma"] = round(cost.per_step / per_step, 3)
    return row


def main() -> int:
    logging.disable(logging.WARNING)
    rows = []
    pend = example_cases(ROOT / "examples", N=STEPS)[0]  # samples scaled until some steps saturate
    rows.append(measure("pendulum", pend.artifact, pend.Y, pend.R))
    for n in (4, 8, 12, 16):
        case = random_case(100 + n, n=n, m=2, p=2, q=1, form="predictor", anti_windup="backcalc", N=STEPS)
        rows.append(measure(f"random_n{n}", case.artifact, case.Y, case.R))
    n12 = next(r for r in rows if r["n"] == 12 and r["design"] != "pendulum")
    per_target = [measure_target(t, pend.artifact, pend.Y, pend.R) for t in CORTEX_M_TARGETS]
    out = {
        "benchmark": "firmware_cost",
        "target": "cortex-m4 (mps2-an386, QEMU TCG plugin: each gl_loop_step call, callees included)",
        "results": rows,
        "per_target": per_target,
        "targets": {
            "pendulum_instructions_per_step_max": 100,
            "pendulum_ok": rows[0]["instructions_per_step"] <= 100,
            "n12_instructions_per_law_mac_max": 2.0,
            "n12_ok": n12["instructions_per_law_mac"] <= 2.0,
        },
    }
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
