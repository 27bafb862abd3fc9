"""What the certified rate of a scheduled law costs at design time (issue 29): CPU seconds of `design` for the
spring of the tests scheduled 1 -> 45, 65, 85 and the showcase (no common Lyapunov function: the rate search
runs), against the example tank (a common Lyapunov function: no search), the baseline measured in the same run;
and what each certifies (rate, pieces, LMIs solved, the falsifier's first growing rate). One process, one BLAS
thread; CPU time (time.process_time) so that other work on a shared machine counts less.

    .venv/bin/python bench/sched_certify.py
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from pathlib import Path

os.environ["OPENBLAS_NUM_THREADS"] = "1"  # before numpy: idle BLAS threads would take CPU time from the design

from gainlink.laws import design as design_spec
from gainlink.spec import load_spec, parse_spec

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from schedule_cases import spring  # noqa: E402


def measure(label: str, spec) -> dict:
    """One design: its CPU seconds and what its verdict on a moving sigma says."""
    t0 = time.process_time()
    art = design_spec(spec).artifact
    seconds = time.process_time() - t0
    v = art["checks"]["schedule"]["variation"]
    search = v["search"] or {}
    return {
        "design": label,
        "cpu_s": round(seconds, 2),
        "rate_max": v["rate_max"],
        "rate_certified": v["rate_certified"],
        "common_lyapunov": v["common_lyapunov"],
        "frozen_pieces": v["frozen"]["pieces"],
        "hull_pieces": search.get("hull_pieces"),
        "lmis_solved": search.get("lmis_solved"),
        "budget_spent": search.get("budget_spent"),
        "falsifier_first_growing_rate": v["falsifier"]["first_growing_rate"],
    }


def main() -> int:
    logging.disable(logging.WARNING)
    tank = ROOT / "examples" / "tank_scheduled.toml"
    measure("warm-up", load_spec(tank))  # the first design imports python-control, scipy.signal, flint, ...
    baseline = measure("tank_scheduled (common P)", load_spec(tank))
    rows = [measure(f"spring 1 -> {k:g}", parse_spec(spring(k))) for k in (45.0, 65.0, 85.0)]
    rows.append(measure("tank_showcase", load_spec(ROOT / "examples" / "tank_showcase.toml")))
    for row in rows:
        row["ratio_to_baseline"] = round(row["cpu_s"] / baseline["cpu_s"], 2)
    print(json.dumps({"benchmark": "sched_certify", "baseline": baseline, "designs": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
