"""Cost of one plant step by kind, against the Co-Simulation FMU step as the baseline measured in the same run.

The project's cart-pendulum FMU stepped through its Co-Simulation interface (RK4 inside doStep; the baseline),
through its Model Exchange interface on fmpy's CVode (``interface = "me"``), the linear plant from the pendulum
spec and the built-in model (its compiled RK4, a batch of one); plus the time ``gainlink linearize`` takes to identify
the Co-Simulation-only Wood-Berry FMU. Prints one JSON document: medians of 5 repeats, ratios to the baseline.

``batch``: the built-in pendulum as a campaign block steps it, 1,000 runs of drawn parameters (``OdeBatch``, the
compiled RK4) against numpy's RK4 over the model's ``rates`` (the kernel it replaced, measured in the same run), thread
CPU per run-step, 2 sub-steps a sample.
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
from gainlink.hil.plants.models import CartPendulum, OdeBatch, columns, rk4

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


def _batch_us(runs: int = 1000, samples: int = 200) -> dict:
    """Thread CPU per run-step of ``runs`` pendulums stepped together, compiled kernel and numpy (medians of 5)."""
    rng = np.random.default_rng(1)
    plants = [CartPendulum(parameters={k: v * rng.uniform(0.7, 1.3) for k, v in CartPendulum.defaults.items()},
                           step=0.005) for _ in range(runs)]  # fmt: skip
    for p in plants:
        p.reset(initial={"x": 1.0, "theta": 0.05})
    U = rng.normal(0.0, 0.5, (samples, runs, 1))
    P = columns(CartPendulum, {k: np.array([p.params[k] for p in plants]) for k in CartPendulum.defaults})
    X0 = np.asfortranarray(np.stack([p.state() for p in plants]))

    def compiled() -> None:
        batch = OdeBatch(plants)
        for k in range(samples):
            batch.advance(U[k], dt=DT)

    def numpy_rk4() -> None:
        X = X0
        for k in range(samples):
            X = rk4(plants[0].rates, X, U[k], P, dt=DT, h=0.005)

    cost = {}
    for name, fn in (("compiled", compiled), ("numpy", numpy_rk4)):
        times = []
        for _ in range(5):
            t0 = time.thread_time()
            fn()
            times.append((time.thread_time() - t0) / samples / runs * 1e6)
        cost[name] = statistics.median(times)
    return {"runs": runs, "per_run_step_cpu_us": {k: round(v, 3) for k, v in cost.items()},
            "numpy_over_compiled": round(cost["numpy"] / cost["compiled"], 2)}  # fmt: skip


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
                "batch": _batch_us(),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
