"""What the design-time checks cost: `design` with and without the float32 closed-loop check.

Prints JSON. For the three examples and random designs with n = 4, 8, 12 (m = p = 2, one integrator):
the median wall time of `design` with the float32 check and without it (the baseline, measured in the
same run; `ratio` is their quotient), and the time per step of the numpy statement of the C's float32
arithmetic (gainlink.laws.lq.model) against the float64 reference law on the same samples. Target: the
check adds at most a few tenths of a second to a design of n <= 12 (ratio reported, no absolute gate).

    .venv/bin/python bench/design_checks.py
"""

from __future__ import annotations

import json
import logging
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

# One BLAS thread, as the gainlink CLI sets for its users (and `make test` for the suite): idle OpenBLAS threads
# spinning after each small product took a core from the timed loop (per-step figures varied 2x between runs).
# Set before numpy is imported.
os.environ["OPENBLAS_NUM_THREADS"] = "1"

import numpy as np
from gainlink.laws import design as design_spec
from gainlink.laws.lq.model import Float32Loop
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping.artifact import from_dict
from gainlink.spec import PlantSpec, load_spec, parse_spec
from gainlink.synthesis.random_plants import random_spec

ROOT = Path(__file__).resolve().parents[1]
REPEAT = 3


def _median_time(fn) -> float:
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def measure(label: str, spec: PlantSpec) -> dict:
    without = replace(spec, implementation=replace(spec.implementation, float32_check=False))
    t_on = _median_time(lambda: design_spec(spec))
    t_off = _median_time(lambda: design_spec(without))
    result = design_spec(spec)
    a = from_dict(result.artifact)
    rng = np.random.default_rng(0)
    Y = a.y_op + rng.standard_normal((500, a.p))
    R = a.r_op + rng.standard_normal((500, a.q))
    t32 = _median_time(lambda: Float32Loop(a).run(Y, R)) / 500
    t64 = _median_time(lambda: ReferenceLoop(a).run(Y, R)) / 500
    return {
        "design": label,
        "n": a.n,
        "m": a.m,
        "p": a.p,
        "q": a.q,
        "design_s_with_float32_check": round(t_on, 4),
        "baseline_design_s_without": round(t_off, 4),
        "ratio": round(t_on / t_off, 2),
        "check_steps": result.float32.steps,
        "float32_law_us_per_step": round(t32 * 1e6, 1),
        "reference_law_us_per_step": round(t64 * 1e6, 1),
        "float32_law_per_reference_step": round(t32 / t64, 2),
        "max_rel_u": result.float32.max_rel_u,
    }


def main() -> int:
    logging.disable(logging.WARNING)
    rows = [
        measure(name, load_spec(ROOT / "examples" / f"{name}.toml"))
        for name in ("pendulum", "quadrotor_lateral", "wood_berry")
    ]
    for n in (4, 8, 12):
        spec = parse_spec(random_spec(n, n=n, m=2, p=2, q=1, anti_windup="backcalc", u_limit=5.0))
        rows.append(measure(f"random_n{n}", spec))
    added = [r["design_s_with_float32_check"] - r["baseline_design_s_without"] for r in rows]
    json.dump(
        {
            "benchmark": "design_checks",
            "rows": rows,
            "median_added_s": round(statistics.median(added), 4),
            "max_added_s": round(max(added), 4),
        },
        sys.stdout,
        indent=2,
    )
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
