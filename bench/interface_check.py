"""Cost of the Co-Simulation check (``interface = "auto"``), against the steps of a run it chooses between.

For FMUs with both interfaces, ``gainlink.hil.plants.fmu_check`` drives Co-Simulation and Model Exchange (CVode at
rtol 1e-10) with the same small input steps once per FMU, step and operating point, then caches the verdict. This
times, in the same run: the check done fresh (cache bypassed), the cached lookup, and one plant step through each
interface (Model Exchange at the plant's default rtol 1e-8). The check's cost is also given in Co-Simulation steps,
the currency of a run that it lets use the cheap interface. The project's cart-pendulum FMU (RK4 Co-Simulation:
kept) at 10 ms and 1 ms. Prints one JSON document, medians of 3 repeats.
"""

from __future__ import annotations

import json
import statistics
import time

import numpy as np
from gainlink.hil.plants.build import build_fmu
from gainlink.hil.plants.fmi import read_description
from gainlink.hil.plants.fmu import FmuPlant
from gainlink.hil.plants.fmu_check import check_cosimulation
from gainlink.hil.plants.fmu_interface import check_setup
from gainlink.hil.plants.fmu_me import FmuModelExchangePlant

REPEATS = 3
STEPS = 300


def _step_us(plant, dt: float) -> float:
    try:
        times = []
        for _ in range(REPEATS):
            plant.reset(initial={"theta": 0.05})
            t0 = time.perf_counter()
            for k in range(STEPS):
                plant.advance(u=np.array([np.sin(0.05 * k)]), dt=dt)
            times.append((time.perf_counter() - t0) / STEPS * 1e6)
        return statistics.median(times)
    finally:
        plant.close()


def _check_seconds(md, setup, step: float) -> tuple[float, float, float]:
    """Fresh (no cache) and cached check times, and the verdict's max difference."""
    fresh = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        result = check_cosimulation(md, setup, step=step, use_cache=False)
        fresh.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    check_cosimulation(md, setup, step=step)
    return statistics.median(fresh), time.perf_counter() - t0, result.max_error


def main() -> None:
    path = build_fmu("cart_pendulum")
    md = read_description(path)
    setup = check_setup(md, plant_args={"path": path}, solver={}, start={})
    out = {}
    for step in (0.01, 0.001):
        cs_us = _step_us(FmuPlant(path=path), step)
        me_us = _step_us(FmuModelExchangePlant(path=path), step)
        fresh, cached, error = _check_seconds(md, setup, step)
        out[f"{step:g}"] = {
            "check_fresh_s": round(fresh, 3),
            "check_cached_s": round(cached, 5),
            "check_in_cs_steps": round(fresh / (cs_us * 1e-6)),
            "max_difference": error,
            "cs_step_us": round(cs_us, 2),
            "me_step_us": round(me_us, 2),
            "me_over_cs": round(me_us / cs_us, 1),
        }
    print(json.dumps({"benchmark": "interface_check", "fmu": "cart_pendulum", "steps": out}, indent=2))


if __name__ == "__main__":
    main()
