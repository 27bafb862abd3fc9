"""Cost of one plant step by kind, against the Co-Simulation FMU step as the baseline measured in the same run.

The project's cart-pendulum FMU stepped through its Co-Simulation interface (RK4 inside doStep; the baseline),
through its Model Exchange interface on fmpy's CVode (``interface = "me"``), the linear plant from the pendulum
spec and the built-in Python model; plus the time ``gainlink linearize`` takes to identify the Co-Simulation-only
Wood-Berry FMU. Prints one JSON document: medians of 5 repeats, ratios to the baseline.
"""

from __future__ import annotations

import json
import statistics
import time
from pathlib import Path

import numpy as np
from gainlink.hil.plants.build import build_fmu
from gainlink.hil.plants.config import plant_from_config
from gainlink.hil.plants.linearize import linearize

ROOT = Path(__file__).resolve().parents[1]
STEPS = 300
DT = 0.01


def _per_step_us(config: dict) -> float:
    plant = plant_from_config(config)
    try:
        times = []
        for _ in range(5):
            plant.reset(initial={"theta": 0.05})
            u = np.zeros(1)
            t0 = time.perf_counter()
            for k in range(STEPS):
                u[0] = np.sin(0.05 * k)
                plant.advance(u=u, dt=DT)
                plant.outputs()
            times.append((time.perf_counter() - t0) / STEPS * 1e6)
        return statistics.median(times)
    finally:
        plant.close()


def main() -> None:
    cart = str(build_fmu("cart_pendulum"))
    wood_berry = build_fmu("wood_berry")
    kinds = {
        "fmu_cs": {"kind": "fmu", "path": cart, "outputs": ["x", "theta"], "interface": "cs"},
        "fmu_me_cvode": {"kind": "fmu", "path": cart, "outputs": ["x", "theta"], "interface": "me"},
        "linear_spec": {"kind": "linear", "spec": str(ROOT / "examples" / "pendulum.toml")},
        "builtin_cart_pendulum": {"kind": "cart_pendulum", "outputs": ["x", "theta"]},
    }
    us = {name: _per_step_us(cfg) for name, cfg in kinds.items()}
    ident = []
    for _ in range(3):
        t0 = time.perf_counter()
        lin = linearize(wood_berry, Ts=1.0)
        ident.append(time.perf_counter() - t0)
    print(
        json.dumps(
            {
                "benchmark": "plant_step",
                "steps": STEPS,
                "dt_s": DT,
                "baseline": "fmu_cs",
                "per_step_us": {k: round(v, 2) for k, v in us.items()},
                "ratio_to_baseline": {k: round(v / us["fmu_cs"], 2) for k, v in us.items()},
                "identify_wood_berry_cs": {
                    "seconds": round(statistics.median(ident), 3),
                    "order": int(lin.A.shape[0]),
                    "horizon_steps": 100,
                },
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
