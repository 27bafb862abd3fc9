"""`pil run` counts the instructions of the law's step on the image it runs (QEMU's TCG plugin, callees included):
for one law of each family on the Cortex-M4F, the counts of a short closed-loop run fall within what the cost
benchmarks recorded for that core and law (bench/results/*_cost.json: an independent measurement of the same step,
replaying samples through the image), and the summary says what the figure is and is not."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.hil.loop.pil_report import pil_summary_text
from gainlink.laws import design as design_spec
from gainlink.shipping.artifact import from_dict, load
from gainlink.spec import parse_spec
from support.fixed import example

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
STEPS = 200


def _recorded(family: str) -> tuple[float, int]:
    """(mean, dearest) instructions per step the cost benchmark recorded for the family's law on the Cortex-M4."""
    if family == "lq/float32":
        row = _m4(json.loads((RESULTS / "firmware_cost.json").read_text())["per_target"])
        return row["instructions_per_step"], row["dearest_step_instructions"]
    if family == "lq/q31":
        row = _m4(json.loads((RESULTS / "fixed_point_cost.json").read_text())["per_target"])
        return row["q31_instructions_per_step"], row["q31_dearest_step_instructions"]
    row = json.loads((RESULTS / "sched_cost.json").read_text())["cortex_m4"]
    return row["scheduled_sigma_standing_instructions_per_step"], row["scheduled_dearest_step_instructions"]


def _m4(rows: list[dict]) -> dict:
    return next(r for r in rows if r["target"] == "cortex-m4")


def _sched_cost_tank():
    """The scheduled tank sched_cost.py measures (5 points on the level), designed here."""
    spec = importlib.util.spec_from_file_location("sched_cost", ROOT / "bench" / "sched_cost.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return from_dict(design_spec(parse_spec(bench.tank_spec())).artifact)


@pytest.mark.slow(cpu=5)
@pytest.mark.parametrize(
    ("family", "symbol"),
    [("lq/float32", "gl_loop_step"), ("lq/q31", "gl_fixed_step"), ("scheduled/float32", "gl_sched_step")],
)
def test_pil_counts_the_steps_instructions_within_the_benchmarks_bounds(example_artifacts, family, symbol):
    if family == "lq/float32":
        a = load(example_artifacts["pendulum"])
    elif family == "lq/q31":
        a = example("pendulum", "q31")
    else:
        a = _sched_cost_tank()
    if family.startswith("scheduled"):  # at rest at the level sched_cost's samples start from, then up to 0.5 m
        x0, reference = np.array([0.4 * np.sqrt(0.05), 0.05]), [0.5]
    else:
        x0, reference = np.full(a.n, 0.05), None
    res = run_pil(a, plant=make_plant("artifact", artifact=a, x0=x0), steps=STEPS, target="cortex-m4",
                  reference=reference, model_twin=False)  # fmt: skip
    block = res.summary()["instructions_per_step"]
    mean, dearest = _recorded(family)
    assert block["symbol"] == symbol and block["calls"] == STEPS
    assert block["fewest"] <= block["mean"] <= block["worst"] <= dearest
    # the same step counted the same way: not a wrapper's handful, not the whole image's loop
    assert 0.8 * mean <= block["mean"] <= dearest
    assert block["own_mean"] <= block["mean"]
    assert "not cycles" in block["covers"]
    text = pil_summary_text({**res.summary(), "artifact": a.name, "sha256": a.sha256, "board": "mps2-an386",
                             "target": "cortex-m4", "plant": "artifact"}, artifact=a)  # fmt: skip
    line = next(x for x in text.splitlines() if "instructions per step" in x)
    assert symbol in line and f"worst {block['worst']}" in line and "not cycles" in line
