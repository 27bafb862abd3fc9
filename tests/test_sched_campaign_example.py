"""examples/campaigns/tank_sigma_rate.toml, run small: the showcase tank's scheduled law (the LPV model of
examples/tank_showcase_load.toml, external sigma) with sigma swept periodically across the whole envelope at rates
around the design's ``rate_max``, the law's own rate limit off (``sigma_rate_limit = false``).

Oracles: the design's verdict (``rate_max`` 2.78/s, certified by a sigma-dependent Lyapunov function; the
falsifier's first growing path at 4.98/s) and the monodromy radius of the whole-envelope triangle at each rate
(0.10 at 2.8/s, 1.24 at 7/s), computed here from the law's loop matrices; the run at 7/s grows from 1 cm past 5 cm,
the others decay.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import LawError
from gainlink.fileio import read_toml
from gainlink.hil.campaign import run
from gainlink.hil.campaign.store import Store
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.laws import design as design_spec
from gainlink.laws import law_of
from gainlink.shipping.artifact import from_dict, load
from gainlink.spec import load_spec
from support.paths import EXAMPLES
from support.shared import once_per_run, shared_lmi_solves

CAMPAIGN = EXAMPLES / "campaigns" / "tank_sigma_rate.toml"
# one worker designs examples/tank_showcase_load.toml for this module and test_schedule_rate_proof's showcase test
pytestmark = [pytest.mark.usefixtures("quiet_design_warnings"), pytest.mark.xdist_group("tank_showcase_load")]


def _designed(factory):
    """examples/tank_showcase_load.toml designed, its certificate's LMI solves shared with the showcase's tank."""
    with shared_lmi_solves(factory):
        return design_spec(load_spec(EXAMPLES / "tank_showcase_load.toml")).artifact


@pytest.fixture(scope="module")
def artifact(tmp_path_factory):
    """examples/tank_showcase_load.toml designed once per test run, saved."""
    made = once_per_run(tmp_path_factory, "tank_showcase_load", lambda: _designed(tmp_path_factory))
    path = tmp_path_factory.mktemp("tank_load") / "gains.json"
    from_dict(made).save(path)
    return path


def _radius(art, rate: float) -> float:
    from gainlink.laws.scheduled.rate import monodromy_radius
    from gainlink.laws.scheduled.variation import loops_at

    up = np.minimum(0.04 + rate * art.Ts * np.arange(1, 1 + int(np.ceil(1.4 / (rate * art.Ts) - 1e-9))), 1.44)
    return monodromy_radius(loops_at(art.schedule, art.Ci), np.concatenate([up, up[::-1][1:], [0.04]]))


@pytest.mark.slow(cpu=31)  # the design (25 CPU-s) and 3 runs
def test_the_example_campaign_holds_up_to_the_verdicts_rates_and_fails_above(artifact, tmp_path):
    art = load(artifact)
    v = art.checks["schedule"]["variation"]
    rate_max = art.schedule.rate_max
    assert art.schedule.rate_certified and rate_max == v["certified_rate"] and 2.5 <= rate_max < 4.0
    data, _ = read_toml(CAMPAIGN, what="campaign", error=ValueError)
    assert data["scenario"]["sigma_rate_limit"] is False and data["grid"][0]["values"][-1] == 7.0
    del data["spec"]
    data["artifact"] = str(artifact)
    data["scenario"]["duration"] = 10.0  # small: 200 steps a run
    data["grid"][0]["values"] = [rate_max, 4.0, 7.0]
    result = run(data, out=tmp_path / "out", workers=1, plots=False)
    assert result.total == 3 and result.errors == 0
    rows = list(result.rows)
    status = {row["values"]["sigma_rate"]: row["status"] for row in rows}
    assert status == {rate_max: "pass", 4.0: "pass", 7.0: "fail"}
    assert _radius(art, rate_max) < 0.2 and _radius(art, 7.0) > 1.2  # the verdict's own measure of the same sweeps
    for row in rows:
        rec = Store(tmp_path / "out").record(row["id"])
        sch = rec["metrics"]["schedule"]
        assert sch["rate_max"] is None and sch["max_rate"] == pytest.approx(row["values"]["sigma_rate"], rel=1e-4)
        assert rec["inputs"]["scenario"]["sigma_rate_limit"] is False


def test_sigma_rate_limit_false_runs_the_law_without_its_rate_max(artifact, example_artifacts):
    """The copy differs only in rate_max (and provenance); the scenario's key is refused for an unscheduled
    artifact in one line."""
    art = load(artifact)
    free = law_of(art).without_rate_limit(art)
    assert free.schedule.rate_max is None and free.sha256 != art.sha256
    assert free.data["provenance"]["rate_limit_removed"] == f"rate_max {art.schedule.rate_max!r} of sha256:{art.sha256}"
    assert np.array_equal(free.schedule.coef["F"], art.schedule.coef["F"]) and free.Ts == art.Ts
    sc = {"artifact": "x", "transport": {}, "duration": 1.0, "plant": {"kind": "cart_pendulum"},
          "sigma_rate_limit": False}  # fmt: skip
    with pytest.raises(LawError) as exc:
        run_scenario(parse_scenario(sc), artifact=load(example_artifacts["pendulum"]))
    assert str(exc.value) == "sigma_rate_limit = false is for a scheduled law; the float32 law has no sigma"
