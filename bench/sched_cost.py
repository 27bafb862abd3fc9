"""Cost of one step of the scheduled law (issue 18 item 7): a 5-point schedule against the unscheduled step of the
same plant, on the Cortex-M4F (instructions per step in QEMU, gainlink.firmware.cost's plugin) and on the host
(nanoseconds per step of the C, one block call of many steps through ctypes).

The design: the example tank (tank_scheduled.toml) with 5 points on its level, h0 = 0.04 ... 1 m (time constant 1 s
to 5 s), sigma its measured level. The unscheduled baseline: the same tank designed at its middle point alone
(today's law, clamp anti-windup; the same n, m, p, q and observer form, checked). Three scheduled runs: sigma moving
on every step (the level sweeping the envelope with noise: every coefficient interpolated every step, the worst
case), sigma standing (a level outside the envelope, clipped: the interpolated coefficients are kept), and the same
sweep with an external sigma. Target (docs/design.md, "Cost"; the issue asked 1.5x): <= 2x the unscheduled step.

    .venv/bin/python bench/sched_cost.py > bench/results/sched_cost.json
"""

from __future__ import annotations

import json
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from gainlink.engines.native import NativeLoop
from gainlink.fileio import read_toml
from gainlink.firmware.build import build
from gainlink.firmware.cost import count_step_instructions
from gainlink.firmware.size import size_report, symbol_sizes
from gainlink.laws import design as design_spec
from gainlink.laws.scheduled.native import NativeScheduledLoop
from gainlink.shipping.artifact import from_dict
from gainlink.spec import parse_spec

ROOT = Path(__file__).resolve().parents[1]
STEPS = 2000
HOST_STEPS = 200_000
LEVELS = (0.04, 0.1, 0.25, 0.5, 1.0)
C_ORIFICE = 0.4
RATIO_MAX = 2.0  # docs/design.md and the shared design's "Cost": <= 2x the unscheduled step


def tank_spec(points=LEVELS, external: bool = False) -> dict:
    """The example tank with a plant per level (the linearisation of its nonlinear model, as the example's)."""
    data, _ = read_toml(ROOT / "examples" / "tank_scheduled.toml", what="spec", error=ValueError)
    data["schedule"]["points"] = list(points)
    data["schedule"]["plant"] = [
        {"A": [[-10.0, 0.0], [1.0, -C_ORIFICE / (2 * np.sqrt(h))]], "B": [[10.0], [0.0]], "C": [[0.0, 1.0]],
         "u_op": [C_ORIFICE * np.sqrt(h)], "y_op": [h], "x_op": [C_ORIFICE * np.sqrt(h), h]}
        for h in points
    ]  # fmt: skip
    if external:
        data["schedule"]["sigma"], data["schedule"]["external"] = "load", ["load"]
    return data


def samples(N: int, *, standing: bool = False):
    """Level samples sweeping the envelope twice with noise, inside it on every step (never clipped: sigma moves on
    every step), or standing above it; reference steps."""
    rng = np.random.default_rng(3)
    t = np.arange(N)
    h = 0.52 - 0.47 * np.cos(2 * np.pi * t / (N / 2)) + 0.002 * rng.standard_normal(N)
    inside = (h.astype(np.float32) > np.float32(LEVELS[0])) & (h.astype(np.float32) < np.float32(LEVELS[-1]))
    assert inside.all() and np.all(np.diff(h) != 0), "the sweep must move inside the envelope on every step"
    Y = (np.full(N, 1.5) if standing else h).reshape(N, 1)
    R = np.where((t // 300) % 2 == 0, 0.3, 0.7).reshape(N, 1)
    return Y, R, h.reshape(N, 1)


def host_ns_per_step(runs: dict, N: int, rounds: int = 5) -> dict:
    """Per run, the best of ``rounds`` block calls of ``N`` steps in nanoseconds per step; the runs take turns in
    each round, so a loaded machine slows them alike."""
    best = dict.fromkeys(runs, np.inf)
    for _ in range(rounds):
        for name, run in runs.items():
            t0 = time.perf_counter()
            run()
            best[name] = min(best[name], time.perf_counter() - t0)
    return {name: t / N * 1e9 for name, t in best.items()}


def main() -> int:
    logging.disable(logging.WARNING)
    spec = parse_spec(tank_spec())
    sched = from_dict(design_spec(spec).artifact)
    ext = from_dict(design_spec(parse_spec(tank_spec(external=True))).artifact)
    mid = spec.at_point(len(LEVELS) // 2)
    plain = from_dict(design_spec(replace(mid, limits=replace(mid.limits, anti_windup="clamp"))).artifact)
    same = ("n", "m", "p", "q", "observer_form")
    assert all(getattr(plain, k) == getattr(sched, k) for k in same), "the baseline is not the same design's"
    Y, R, H = samples(STEPS)
    Ys, _, _ = samples(STEPS, standing=True)
    elf_s = build(sched, target="cortex-m4").files["elf"]
    elf_e = build(ext, target="cortex-m4").files["elf"]
    elf_p = build(plain, target="cortex-m4").files["elf"]
    base = count_step_instructions(elf_p, plain, Y=Y, R=R)
    moving = count_step_instructions(elf_s, sched, Y=Y, R=R)
    standing = count_step_instructions(elf_s, sched, Y=Ys, R=R)
    external = count_step_instructions(elf_e, ext, Y=Y, R=R, S=H)
    Yh, Rh, _ = samples(HOST_STEPS)
    nat_p, nat_s = NativeLoop(plain), NativeScheduledLoop(sched)
    Yhs, _, _ = samples(HOST_STEPS, standing=True)
    host = host_ns_per_step({"plain": lambda: nat_p.run_raw(Yh, Rh), "moving": lambda: nat_s.run_raw(Yh, Rh),
                             "standing": lambda: nat_s.run_raw(Yhs, Rh)}, HOST_STEPS)  # fmt: skip
    host_p, host_s, host_st = host["plain"], host["moving"], host["standing"]
    size_s = size_report(elf_s, board="mps2-an386")
    m4 = {
        "unscheduled_instructions_per_step": round(base.per_step, 2),
        "scheduled_sigma_moving_instructions_per_step": round(moving.per_step, 2),
        "scheduled_sigma_standing_instructions_per_step": round(standing.per_step, 2),
        "scheduled_external_sigma_moving_instructions_per_step": round(external.per_step, 2),
        "ratio_sigma_moving": round(moving.per_step / base.per_step, 3),
        "ratio_sigma_standing": round(standing.per_step / base.per_step, 3),
        "scheduled_dearest_step_instructions": moving.dearest,
        "scheduled_image_flash_bytes": size_s["flash_bytes"],  # replay only: no bus node (the unscheduled has two)
        "scheduled_image_ram_bytes_without_stack": size_s["ram_bytes_without_stack"],
        "scheduled_step_code_bytes": symbol_sizes(elf_s, ("gl_sched_step",))["gl_sched_step"]["size"],
        "scheduled_tables_bytes": symbol_sizes(elf_s, ("gl_sched_default",))["gl_sched_default"]["size"],
    }
    out = {
        "benchmark": "sched_cost",
        "design": f"tank, {len(LEVELS)} points on the level {list(LEVELS)}, n=2 m=1 p=1 q=1, predictor; baseline: "
        "the same tank designed at h0 = 0.25 alone (clamp)",
        "cortex_m4": m4,
        "host": {
            "steps": HOST_STEPS,
            "unscheduled_ns_per_step": round(host_p, 1),
            "scheduled_sigma_moving_ns_per_step": round(host_s, 1),
            "scheduled_sigma_standing_ns_per_step": round(host_st, 1),
            "ratio_sigma_moving": round(host_s / host_p, 3),
            "ratio_sigma_standing": round(host_st / host_p, 3),
        },
        "targets": {
            "ratio_max": RATIO_MAX,
            "sigma_moving_ok": m4["ratio_sigma_moving"] <= RATIO_MAX,
            "sigma_standing_ok": m4["ratio_sigma_standing"] <= RATIO_MAX,
        },
    }
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
