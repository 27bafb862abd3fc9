"""The scheduled law's float32 fidelity at design time (gainlink.laws.scheduled.fidelity): the C's float32
arithmetic and the float64 law, each in closed loop around the design model frozen at each sigma of a sweep.

Oracles: the sweep's sigmas written out by hand (the points and the middle of each interval); the real host C
(``gl_sched.c`` through ctypes) in place of the numpy float32 model gives the recorded figures exactly (it is the model
bit for bit); a law whose commands are rounded to 1/256 of the span (an error of up to 1/512 of it on every step, eight
times the threshold) is a warning naming where.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.laws import law_of
from gainlink.laws.lq.fidelity import THRESHOLD
from gainlink.laws.scheduled.fidelity import scheduled_fidelity
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.shipping.artifact import from_dict
from schedule_cases import external_tank, tank_dict
from support.designs import designed

pytestmark = pytest.mark.xdist_group("test_sched_fidelity")

#: examples/tank_scheduled.toml's points and the middle of each interval between them.
TANK_SWEEP = [0.04, 0.145, 0.25, 0.625, 1.0]


@pytest.fixture(scope="module")
def level():
    """The example tank, scheduled on its measured level."""
    return from_dict(designed(tank_dict()))


@pytest.fixture(scope="module")
def external():
    """The tank scheduled on an external signal (current form, sigma filtered and rate-limited)."""
    return from_dict(designed(external_tank(form="current", rate_max=4.0, filter_tau=0.1)))


def test_design_records_the_float32_fidelity_at_each_sigma_of_the_sweep(level, external):
    for a in (level, external):
        f32 = a.checks["float32"]
        assert [run["sigma"] for run in f32["sweep"]] == pytest.approx(TANK_SWEEP, abs=1e-12)
        worst = max(f32["sweep"], key=lambda run: run["max_rel_u"])
        assert (f32["sigma"], f32["max_rel_u"]) == (worst["sigma"], worst["max_rel_u"])
        assert 0.0 < f32["max_rel_u"] < THRESHOLD and f32["threshold"] == THRESHOLD  # not free, only small
        assert f32["saturated_fraction"] > 0  # the scenario's disturbance saturates the pump


def test_the_recorded_figures_are_what_the_host_c_does_in_the_same_loops(external):
    """The host build of gl_sched.c closing the same loops at the same sigmas: the same deviations, exactly."""
    law = law_of(external)
    real = scheduled_fidelity(external, implementation=lambda a: law.native(a))
    assert [(s, f.max_rel_u, f.max_rel_y) for s, f in real.sweep] == [
        (run["sigma"], run["max_rel_u"], run["max_rel_y"]) for run in external.checks["float32"]["sweep"]
    ]


class _Coarse:
    """The float32 model with its commands rounded to 1/256 of the limit span (a law whose arithmetic costs)."""

    def __init__(self, a) -> None:
        self.loop, self.step_u = ScheduledFloat32Loop(a), (a.u_max - a.u_min) / 256

    def step(self, y, r, s):
        res = self.loop.step(y, r, s)
        return type(res)(**{**res.__dict__, "u": np.round(res.u / self.step_u) * self.step_u})


def test_a_law_whose_arithmetic_costs_more_than_the_threshold_is_a_warning_naming_where(level):
    fid = scheduled_fidelity(level, implementation=_Coarse)
    assert not fid.ok and fid.max_rel_u > THRESHOLD
    sigma, worst = fid.worst
    warning = fid.warning("h")
    assert f"at h = {sigma:g} the C's command deviates" in warning and f"{worst.max_rel_u:.3g}" in warning
    assert "realization" not in warning  # a scheduled law keeps its points' coordinates: not a remedy


def test_the_spec_switches_it_off():
    data = tank_dict()
    data["implementation"] = {"float32_check": False}
    assert "float32" not in designed(data)["checks"]
