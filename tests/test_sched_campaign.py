"""A campaign over a scheduled artifact's sigma rate and range (SIL with the scheduled C, a LocalCluster of one
worker).

The plant is the spring of schedule_cases (stiffness scheduled 1 -> 400 on an external sigma; no rate certified
within the default refinements, so its spec declares a rate uncertified: 0.5/s, the rate the old simulated verdict
gave) run as ``kind = "lpv_model"``, whose dynamics follow the external signal; the law is the same design
with ``rate_max`` removed, so the signal's own rate is the rate sigma moves at. Oracles: the falsifier's sweeps
(stable at 0.5/s over every sub-range on its grid) and the direct SIL run of each campaign run.

What the campaign finds (measured, and checked with the verdict's own loop outside SIL: the scheduled law around
``Schedule.plant_at`` on a triangle over [0, 0.5] at 1.58/s grows from 7e-3 to 34 in 60 periods): the rate a
verdict gave when it simulated sweeps over the whole envelope and each interval only, 1.58/s, holds across the
whole envelope, but a sweep over half of it at that rate drives the loop into a saturated limit cycle (|x| ~ 27
from 0.01). Periodic sigma is a parametric excitation: a rate bound from full-envelope trajectories alone is not a
bound for every trajectory, which is why the falsifier sweeps every sub-range on a grid (and why a shipped rate is
a certified one, or said not to be): 0.5/s holds on both ranges.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from gainlink.hil.campaign import run
from gainlink.hil.campaign.store import Store
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.shipping.artifact import from_dict, seal
from schedule_cases import spring
from support.designs import designed

OLD_RATE = 50.0 * 10**-1.5  # the rate_max of the verdict that swept only the whole envelope and each interval
pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


@pytest.fixture(scope="module")
def spring_free(tmp_path_factory):
    """The spring's artifact without its rate limit, saved; and its declared (uncertified) ``rate_max``."""
    spec = spring(400.0)
    spec["schedule"].update(rate_max=0.5, rate_certified=False)
    data = designed(spec)
    rate_max = data["schedule"]["rate_max"]
    assert not data["schedule"]["rate_certified"]
    free = from_dict(seal(dict(data, schedule=dict(data["schedule"], rate_max=None))))
    path = tmp_path_factory.mktemp("spring") / "gains.json"
    free.save(path)
    return path, rate_max


def _campaign(path, rate_max: float) -> dict:
    sweep = {"kind": "sweep", "low": 0.0, "high": 1.0, "rate": 1.0, "cycles": 1000}
    return {
        "name": "spring_sigma",
        "kind": "sil",
        "seed": 3,
        "artifact": str(path),
        "scenario": {
            "duration": 10.0,
            "controller": "firmware",  # the scheduled C of the host library, built on the worker
            "twin": False,
            "model_twin": False,
            "plant": {"kind": "lpv_model"},
            "initial_state": {"x": 0.01},
            "schedule_signal": {"k": sweep},
        },
        "grid": [
            {"name": "sigma_rate", "targets": ["schedule_signal.k.rate"], "values": [rate_max, OLD_RATE]},
            {"name": "sigma_high", "targets": ["schedule_signal.k.high"], "values": [0.5, 1.0]},
        ],
        "criteria": {"stable": True, "bounds": {"x": [-1.0, 1.0]}},  # a saturated limit cycle does not grow
    }


@pytest.mark.slow(cpu=8)
def test_a_campaign_over_sigma_rate_and_range_finds_where_stability_stops(spring_free, tmp_path):
    path, rate_max = spring_free
    result = run(_campaign(path, rate_max), out=tmp_path / "out", workers=1, plots=False)
    assert result.total == 4 and result.errors == 0
    rows = list(result.rows)
    verdict = {(row["values"]["sigma_rate"], row["values"]["sigma_high"]): row["status"] for row in rows}
    # at the declared rate_max the loop holds on both ranges; at the old verdict's rate it holds across the whole
    # envelope and not over its lower half (the module docstring)
    assert rate_max < OLD_RATE
    assert verdict == {
        (rate_max, 0.5): "pass",
        (rate_max, 1.0): "pass",
        (OLD_RATE, 0.5): "fail",
        (OLD_RATE, 1.0): "pass",
    }
    assert all("bounds" in row["failed"] for row in rows if row["status"] == "fail")
    for row in rows:
        rec = Store(tmp_path / "out").record(row["id"])
        sch = rec["metrics"]["schedule"]
        step = row["values"]["sigma_rate"] * 0.02  # sigma per sample (Ts = 0.02 s): the turn falls between samples
        assert row["values"]["sigma_high"] - step <= sch["sigma_max"] <= row["values"]["sigma_high"]
        assert sch["max_rate"] == pytest.approx(row["values"]["sigma_rate"], rel=1e-5)  # sigma in float32
        sc = parse_scenario(dict(rec["inputs"]["scenario"], artifact=str(path), transport={}, seed=row["seed"]))
        direct = run_scenario(sc, artifact=from_dict(json.loads(path.read_text())))
        assert direct.metrics["outputs_final"] == rec["metrics"]["outputs_final"]
        assert np.isfinite(direct.trace.y).all()
