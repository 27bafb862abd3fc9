"""The plan's run ids made from each grid point's id template (one canonical JSON text with a slot per drawn value)
are the ids of the runs made whole.

Oracles: the run made whole (``_Planner.point``: its scenario built and its body through ``json.dumps``), and for
one campaign the id worked out by hand from the run's definition (the base scenario with the values set, scaled,
shifted).
"""

from __future__ import annotations

import copy
import hashlib
import json

import numpy as np
import pytest
from gainlink.hil.campaign import parse_campaign
from gainlink.hil.campaign import plan as plan_module
from gainlink.hil.campaign.plan import draw_values, plan_campaign
from gainlink.version import __version__
from support.paths import EXAMPLES

RUNS = 40
BASE = {
    "duration": 0.5,
    "plant": {"kind": "cart_pendulum", "outputs": ["x", "theta"], "parameters": {"M": 1.0, "m": 0.1, "l": 0.5}},
}
SCALE_M = {"target": "plant.parameters.M", "distribution": "uniform", "low": 0.7, "high": 1.3, "apply": "scale"}
ADD_M = {"target": "plant.parameters.m", "distribution": "normal", "mean": 0.0, "std": 0.005, "apply": "add"}
SET_L = {"target": "plant.parameters.l", "distribution": "truncnormal", "mean": 0.5, "std": 0.02, "low": 0.45,
         "high": 0.55}  # fmt: skip
NEW_PATH = {"target": "noise.x", "distribution": "choice", "values": [1, 0.002, 0]}  # an int, a float; a new table
SIGNED_ZEROS = {"target": "noise.x", "distribution": "choice", "values": [0, -0.0, 0.0, 0.002]}  # equal, 3 texts
LOG_M = {"target": "plant.parameters.M", "distribution": "loguniform", "low": 0.8, "high": 1.25, "apply": "scale"}
GRID_X = {"target": "initial_state.x", "values": [0.2, 1.0]}


def _campaign(spec: str, grid: list, draws: list, runs: int = RUNS) -> dict:
    return {"name": "ids", "kind": "sil", "seed": 5, "runs": runs, "spec": spec, "scenario": copy.deepcopy(BASE),
            "grid": grid, "draw": draws, "criteria": {"stable": True}}  # fmt: skip


@pytest.mark.parametrize(
    ("grid", "draws", "templated"),
    [
        ([GRID_X], [SCALE_M, ADD_M, SET_L, NEW_PATH], True),
        ([GRID_X], [LOG_M, SIGNED_ZEROS], True),
        ([{"target": "spec.limits.anti_windup", "values": ["clamp", "none"]}], [SCALE_M, NEW_PATH], True),
        ([{"name": "M", "target": "plant.parameters.M", "values": [0.9, 1.1]}], [SCALE_M], False),  # one path, 2 axes
    ],
)
def test_the_planned_ids_are_the_ids_of_the_runs_made_whole(grid, draws, templated):
    """Every run's planned id and design flag against the run made whole (its scenario built, its body through
    json's encoder), for draws that scale, shift and set values and make a new table, a grid over the spec, and a
    campaign whose two axes touch one path (each run made: the template is not used there)."""
    campaign = parse_campaign(_campaign(str(EXAMPLES / "pendulum.toml"), grid, draws))
    plan = plan_campaign(campaign)
    assert plan_module._templated(campaign) is templated
    planner = plan.runs._planner
    made = [planner.point(k) for k in range(len(plan.runs))]
    assert plan.runs.ids.tolist() == [p.id.encode("ascii") for p in made]
    assert plan.runs.failed.tolist() == [p.error is not None for p in made]
    assert len(set(plan.runs.ids.tolist())) == len(plan.runs)


def test_a_planned_id_is_the_hash_of_the_runs_definition_worked_by_hand():
    """Run k's id from its definition: draw j's values (:func:`draw_values`, its chunk's), the base with M scaled, m
    shifted, l set and noise.x a new table, initial_state.x the grid's; the body's canonical JSON and sha256."""
    campaign = parse_campaign(_campaign(str(EXAMPLES / "pendulum.toml"), [GRID_X], [SCALE_M, ADD_M, SET_L, NEW_PATH]))
    plan = plan_campaign(campaign)
    (sha,) = plan.artifacts
    for k in (0, 1, RUNS - 1, RUNS, 2 * RUNS - 1):
        g, j = divmod(k, RUNS)
        seed, v = draw_values(campaign, j)
        scenario = copy.deepcopy(BASE)
        p = scenario["plant"]["parameters"]
        p["M"] *= v["plant.parameters.M"]
        p["m"] += v["plant.parameters.m"]
        p["l"] = v["plant.parameters.l"]
        scenario["noise"] = {"x": v["noise.x"]}
        scenario["initial_state"] = {"x": GRID_X["values"][g]}
        body = {"kind": "sil", "artifact": sha, "scenario": scenario, "seed": seed, "gainlink": __version__}
        text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
        assert plan.runs.ids[k] == hashlib.sha256(text.encode("ascii")).hexdigest()[:20].encode("ascii"), k
    assert {type(v) for v in (draw_values(campaign, j)[1]["noise.x"] for j in range(RUNS))} == {int, float}
    assert np.unique(plan.runs.ids).size == len(plan.runs)


def test_the_draw_table_holds_each_draws_values_drawn_from_its_chunks_generator():
    """Draw j's seed and values, worked from the definition with scipy's distributions made anew for each chunk:
    draws come in chunks of 1,024, chunk c from ``default_rng([seed, c])``: its 1,024 run seeds first, then each
    axis's 1,024 values in order from the same generator; a campaign of 1,500 runs spans two chunks, and its first
    400 draws are those of a campaign of 400 (raising ``runs`` keeps the earlier draws)."""
    from scipy import stats

    scale_m = SCALE_M | {"target": "plant.parameters.m"}
    axes = [SET_L, LOG_M, scale_m, NEW_PATH]
    campaign = parse_campaign(_campaign(str(EXAMPLES / "pendulum.toml"), [], axes, runs=1500))
    seeds, cols = plan_module.draw_table(campaign)
    assert seeds.shape == (1500,) and all(col.shape == (1500,) for col in cols.values())
    lo, hi = (0.45 - 0.5) / 0.02, (0.55 - 0.5) / 0.02
    for c in (0, 1):
        rng = np.random.default_rng([5, c])
        chunk = slice(1024 * c, min(1024 * (c + 1), 1500))
        n = chunk.stop - chunk.start
        assert seeds[chunk].tolist() == rng.integers(2**31 - 1, size=1024)[:n].tolist()
        l_ = stats.truncnorm(lo, hi, loc=0.5, scale=0.02).rvs(size=1024, random_state=rng)
        assert cols["plant.parameters.l"][chunk].tolist() == l_[:n].tolist()
        M = stats.loguniform(0.8, 1.25).rvs(size=1024, random_state=rng)
        assert cols["plant.parameters.M"][chunk].tolist() == M[:n].tolist()
        assert cols["plant.parameters.m"][chunk].tolist() == rng.uniform(0.7, 1.3, size=1024)[:n].tolist()
        assert cols["noise.x"][chunk].tolist() == rng.integers(3, size=1024)[:n].tolist()
    fewer = parse_campaign(_campaign(str(EXAMPLES / "pendulum.toml"), [], axes))
    few_seeds, few_cols = plan_module.draw_table(fewer)
    assert few_seeds.tolist() == seeds[:RUNS].tolist()
    assert all(few_cols[name].tolist() == col[:RUNS].tolist() for name, col in cols.items())
