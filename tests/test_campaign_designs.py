"""A campaign's laws are designed once a process (:mod:`gainlink.hil.campaign.designs`): a campaign planned again
takes the artifacts it designed, a changed spec is designed anew, a refused spec is refused again, and what is kept
is bounded.

Oracle: the design itself (a plan made after the kept artifacts are dropped designs again, and must give the same
bytes: the design is deterministic, which is what makes keeping it sound).
"""

from __future__ import annotations

import copy

import pytest
from gainlink.errors import GainlinkError
from gainlink.hil.campaign import designs, parse_campaign
from gainlink.hil.campaign.plan import plan_campaign
from support.paths import EXAMPLES

CAMPAIGN = {
    "name": "designs",
    "kind": "sil",
    "seed": 3,
    "runs": 4,
    "spec": str(EXAMPLES / "pendulum.toml"),
    "scenario": {
        "duration": 0.2,
        "plant": {"kind": "cart_pendulum", "outputs": ["x", "theta"], "parameters": {"M": 1.0}},
    },
    "grid": [{"target": "spec.limits.anti_windup", "values": ["clamp", "none"]}],
    "draw": [{"target": "plant.parameters.M", "distribution": "uniform", "low": 0.8, "high": 1.2, "apply": "scale"}],
    "criteria": {"stable": True},
}


def _refusing(*_args, **_kwargs):
    raise AssertionError("designed again")


@pytest.fixture
def no_kept(monkeypatch):
    """The process's kept designs, empty for the test (and the ones kept before put back after it)."""
    monkeypatch.setattr(designs, "_designed", type(designs._designed)())


def test_a_campaign_planned_again_takes_its_laws_without_designing_them_and_the_same_artifacts(no_kept, monkeypatch):
    first = plan_campaign(parse_campaign(copy.deepcopy(CAMPAIGN)))
    assert len(first.artifacts) == 2  # one law a grid point
    designed = dict(first.artifacts)
    ids = [first.runs[k].id for k in range(len(first.runs))]
    with monkeypatch.context() as m:
        m.setattr(designs, "_design", _refusing)
        again = plan_campaign(parse_campaign(copy.deepcopy(CAMPAIGN)))
    assert dict(again.artifacts) == designed
    assert [again.runs[k].id for k in range(len(again.runs))] == ids
    designs._designed.clear()  # designed anew: the same bytes
    assert dict(plan_campaign(parse_campaign(copy.deepcopy(CAMPAIGN))).artifacts) == designed


def test_a_spec_changed_in_one_number_is_designed_anew(no_kept, monkeypatch):
    plan_campaign(parse_campaign(copy.deepcopy(CAMPAIGN)))
    changed = copy.deepcopy(CAMPAIGN)
    changed["grid"] = [{"target": "spec.limits.anti_windup", "values": ["backcalc"]}]  # neither designed
    calls = []
    real = designs._design
    monkeypatch.setattr(designs, "_design", lambda spec, source: calls.append(source) or real(spec, source=source))
    plan = plan_campaign(parse_campaign(changed))
    assert len(calls) == 1 and len(plan.artifacts) == 1


def test_a_refused_spec_is_not_kept_and_is_refused_again(no_kept, monkeypatch):
    calls = []

    def refusing(spec, *, source):
        calls.append(source)
        raise GainlinkError("no such law")

    monkeypatch.setattr(designs, "_design", refusing)
    for _ in range(2):
        with pytest.raises(GainlinkError):
            designs.designed({"a": 1}, source="x.toml")
    assert calls == ["x.toml", "x.toml"] and not designs._designed


def test_the_kept_designs_are_bounded_and_the_least_recently_planned_goes_first(no_kept, monkeypatch):
    calls = []
    monkeypatch.setattr(designs, "_design", lambda spec, source: calls.append(spec["k"]) or str(spec["k"]).encode())
    for k in range(designs.KEPT):
        designs.designed({"k": k}, source="s")
    designs.designed({"k": 0}, source="s")  # planned again: now the most recent
    designs.designed({"k": designs.KEPT}, source="s")  # one past the bound: drops k = 1, not k = 0
    assert len(designs._designed) == designs.KEPT
    calls.clear()
    assert designs.designed({"k": 0}, source="s") == b"0" and calls == []
    assert designs.designed({"k": 1}, source="s") == b"1" and calls == [1]
