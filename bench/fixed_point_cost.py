"""The fixed-point law against float32 on the Cortex-M cores: instructions per step in QEMU, flash and RAM.

Prints JSON. The pendulum example (Kalman, integral action, back-calculation) designed with ``[implementation]
numeric = "q31"`` (its certificate in the artifact). Its image runs the integer law (``gl_fixed_step``, the unrolled
variant: the replay-only image, ``GL_IMAGE_SERVE=OFF``); the float32 baseline is the same export built with
``GL_LAW=lq_float32`` (``gl_loop_step``: the export holds the float gains too), both run on the same 2000 samples
(those of ``bench/firmware_cost.py``; the q31 law clips them to the declared ranges).
Instructions are counted from each call of the step to its return, callees included (gainlink.firmware.cost), so
the soft-float routines of the M0 and M3 and the float conversions of the fixed step are in the count.

For each core: q31 instructions per step (mean, dearest, inside the step's own symbol), the float32 step as built
(every multiply-add a correctly rounded ``gl_fmaf`` on the M0 and M3, bit for bit with the host; ``vfma.f32`` on
the M4) and, on the soft-float cores, the float32 step with a plain multiply then add (docs/design.md: the
baseline of the >= 3x target), the ratios float32 / q31, and flash and RAM of both images. Target: on the M0,
q31 >= 3x fewer instructions than the plain float32 step.

    .venv/bin/python bench/fixed_point_cost.py
"""

from __future__ import annotations

import copy
import json
import logging
import sys
from pathlib import Path

from gainlink.fileio import read_toml
from gainlink.firmware.build import build
from gainlink.firmware.cost import count_step_instructions
from gainlink.firmware.size import size_report, symbol_sizes
from gainlink.firmware.targets import TARGETS
from gainlink.laws import design as design_spec
from gainlink.laws.fixed import firmware as fixed
from gainlink.laws.lq.golden import example_cases
from gainlink.shipping.artifact import from_dict
from gainlink.spec import parse_spec

ROOT = Path(__file__).resolve().parents[1]
STEPS = 2000
CORES = ("cortex-m0", "cortex-m3", "cortex-m4")


def pendulum_q31():
    data, _ = read_toml(ROOT / "examples" / "pendulum.toml", what="spec", error=ValueError)
    data = copy.deepcopy(data)
    data["implementation"] = {"numeric": "q31"}
    return from_dict(design_spec(parse_spec(data)).artifact)


def _size(elf: Path, board: str, symbols: tuple[str, ...]) -> dict:
    size = size_report(elf, board=board)
    code = symbol_sizes(elf, symbols)
    return {
        "flash_bytes": size["flash_bytes"],
        "ram_bytes_without_stack": size["ram_bytes_without_stack"],
        "ram_bytes": size["ram_bytes"],
        "symbol_bytes": {k: v["size"] for k, v in code.items()},
    }


#: The float32 baseline of the q31 artifact: its export's float gains, the law alone (cmake/law.cmake).
BASELINE = {"GL_LAW": "lq_float32", "GL_IMAGE_SERVE": "OFF"}


def measure(target: str, artifact, Y, R) -> dict:
    board = TARGETS[target].default_board
    fpu = TARGETS[target].hardware_fma
    elf_q, _ = fixed.image(artifact, target=target, options=fixed.REPLAY_OPTIONS)
    q = count_step_instructions(elf_q, artifact, Y=Y, R=R, board=board)
    elf_f = build(artifact, target=target, options=BASELINE).files["elf"]
    f = count_step_instructions(elf_f, artifact, Y=Y, R=R, board=board, law="lq/float32")
    row = {
        "target": target,
        "board": board,
        "fpu": fpu,
        "q31_instructions_per_step": round(q.per_step, 1),
        "q31_dearest_step_instructions": q.dearest,
        "q31_own_instructions_per_step": round(q.own_per_step, 1),
        "float32_instructions_per_step": round(f.per_step, 1),
        "ratio_float32_to_q31": round(f.per_step / q.per_step, 2),
        "q31_image": _size(elf_q, board, ("gl_fixed_step", "gl_fixed_default")),
        "float32_image": _size(elf_f, board, ("gl_loop_step", "gl_gains_default")),
    }
    if not fpu:
        plain = build(artifact, target=target, options=BASELINE | {"GL_SOFT_FMA": "plain"}).files["elf"]
        p = count_step_instructions(plain, artifact, Y=Y, R=R, board=board, law="lq/float32")
        row["float32_plain_fma_instructions_per_step"] = round(p.per_step, 1)
        row["ratio_float32_plain_to_q31"] = round(p.per_step / q.per_step, 2)
    return row


def main() -> int:
    logging.disable(logging.WARNING)
    artifact = pendulum_q31()
    pend = example_cases(ROOT / "examples", N=STEPS)[0]
    rows = [measure(t, artifact, pend.Y, pend.R) for t in CORES]
    m0 = rows[0]
    fp = artifact.checks["fixed_point"]
    out = {
        "benchmark": "fixed_point_cost",
        "design": "pendulum (Kalman, LQI, back-calculation), numeric q31",
        "certificate": {"case": fp["case"], "error_fraction_of_span": fp["error"]["fraction_of_span"]},
        "steps": STEPS,
        "per_target": rows,
        "targets": {
            "m0_ratio_float32_plain_to_q31_min": 3.0,
            "m0_ok": m0["ratio_float32_plain_to_q31"] >= 3.0,
        },
    }
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
