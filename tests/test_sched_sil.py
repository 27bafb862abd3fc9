"""The scheduled law in the software-in-the-loop path (in process, gainlink.hil.loop.bridge) on the nonlinear tank of
examples/tank_scheduled.toml (kind = "tank": its level's time constant grows 5x across the envelope).

Oracles: the float64 scheduled law as the closed-loop twin of the C; sigma recomputed here from the measured level
or the scenario's profile (clip and rate limit written out by hand); the single-point designs of the same plant
(one per schedule point, unscheduled, through the existing SIL path) on the same runs.
"""

from __future__ import annotations

import copy
import json

import gainlink.hil
import numpy as np
import pytest
from gainlink.errors import ScenarioError
from gainlink.fileio import read_toml
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario, resolve_scenario_path
from gainlink.shipping.artifact import from_dict
from schedule_cases import external_tank, tank_dict
from support.cli import assert_refused, run_cli
from support.designs import designed
from support.hil import udp_transport, write_scenario

# One worker runs this module (make test: --dist loadgroup): the tank designs, made once.
# one worker runs the module (17 CPU-s): started first
pytestmark = [
    pytest.mark.usefixtures("quiet_design_warnings"),
    pytest.mark.xdist_group("test_sched_sil"),
    pytest.mark.slow(cpu=17),
]
C_ORIFICE = 0.4  # the tank's orifice coefficient: equilibrium q = u = c sqrt(h)


def single_point(i: int) -> dict:
    """The unscheduled design of the tank at schedule point ``i`` (same weights, clamp anti-windup)."""
    data = tank_dict()
    pt = data.pop("schedule")["plant"][i]
    data["plant"].update({k: copy.deepcopy(pt[k]) for k in ("A", "B", "C")})
    data["operating_point"] = {k: pt[k] for k in ("u_op", "y_op", "x_op")}
    data["limits"]["anti_windup"] = "clamp"
    data["name"] = f"tank_at_point_{i}"
    return data


@pytest.fixture(scope="module")
def tank():
    return from_dict(designed(tank_dict()))


@pytest.fixture(scope="module")
def singles():
    return [from_dict(designed(single_point(i))) for i in range(3)]


@pytest.fixture(scope="module")
def external():
    """The tank scheduled on an external signal: limited to 0.05 /s, and free."""
    return {r: from_dict(designed(external_tank(rate_max=r))) for r in (0.05, None)}


def _scenario(duration: float, h0: float, reference: dict, **extra) -> object:
    data = {
        "artifact": "unused.json",
        "transport": {},
        "plant": {"kind": "tank", "step": 0.005},
        "duration": duration,
        "controller": "reference",
        "initial_state": {"q": C_ORIFICE * np.sqrt(h0), "h": h0},
        "reference": {"r_h": reference},
    }
    return parse_scenario(data | extra)


def _sweep(rate: float, start: float = 2.0) -> dict:
    return {"kind": "sweep", "low": 0.04, "high": 1.0, "rate": rate, "start": start}


def test_a_reference_sweep_across_the_envelope_tracks_and_sigma_covers_it(tank):
    res = run_scenario(_scenario(45.0, 0.04, _sweep(0.05)), artifact=tank)
    m, tr = res.metrics, res.trace
    assert res.complete
    sch = m["schedule"]
    assert sch["sigma"] == "h" and sch["source"] == "output"
    assert sch["sigma_min"] == pytest.approx(0.04) and sch["sigma_max"] > 0.97 and sch["coverage"] > 0.95
    assert sch["held_steps"] == sch["clipped_steps"] == sch["rate_limited_steps"] == 0
    # sigma is the measured level itself (no filter, no rate limit), clipped into the envelope
    assert np.array_equal(tr.sigma, np.clip(tr.y[:, 0], 0.04, 1.0))
    moving = tr.t >= 2.0
    assert np.max(np.abs(tr.r[moving, 0] - tr.y[moving, 0])) < 0.04  # measured 0.036 at 0.05 m/s
    # The model twin (the law around the points' models interpolated at its sigma) follows the tank closely
    assert m["model_twin"]["worst"] < 0.005 and not m["model_twin"]["warning"]
    assert m["twin"]["worst_du_rel"] == 0.0  # the controller is the float64 law itself


def test_the_scheduled_c_closes_the_loop_as_its_float64_twin(tank):
    res = run_scenario(_scenario(14.0, 0.04, _sweep(0.2, start=1.0), controller="firmware"), artifact=tank)
    m = res.metrics
    assert res.complete and res.info["controller"]["kind"].startswith("firmware (host scheduled C")
    assert m["twin"]["worst_du_rel"] < 1e-5 and m["twin"]["worst_dy_rel"] < 1e-5
    assert m["schedule"]["coverage"] > 0.9  # measured 0.93: at 0.2 m/s the level lags the sweep's turn
    assert np.allclose(res.trace.sigma, np.clip(res.trace.y[:, 0], 0.04, 1.0), rtol=0, atol=1e-6)  # float32


def _step_iae(art, h0: float, h1: float) -> float:
    """IAE of the level after a reference step h0 -> h1 at t = 20 s, from equilibrium at h0."""
    sc = _scenario(40.0, h0, {"kind": "step", "initial": h0, "value": h1, "at": 20.0}, twin=False, model_twin=False)
    res = run_scenario(sc, artifact=art)
    after = res.trace.t >= 20.0
    return float(np.sum(np.abs(h1 - res.trace.y[after, 0])) * art.Ts)


@pytest.mark.parametrize("h0, h1", [(0.1, 0.9), (0.9, 0.1)])
def test_across_the_envelope_the_scheduled_design_beats_every_single_point_design(tank, singles, h0, h1):
    sched = _step_iae(tank, h0, h1)
    each = [_step_iae(a, h0, h1) for a in singles]
    # measured: 0.1 -> 0.9: 0.649 against 0.665, 0.702, 0.725; 0.9 -> 0.1: 1.210 against 1.288, 1.315, 1.347
    assert sched < 0.985 * min(each), (sched, each)


def test_about_a_schedule_point_the_scheduled_design_is_that_points_design(tank, singles):
    # a small step from the point: sigma moves by 0.05 with the level, so equal to 0.13 % (measured), not exactly
    assert _step_iae(tank, 0.25, 0.3) == pytest.approx(_step_iae(singles[1], 0.25, 0.3), rel=5e-3)


def test_an_external_sigma_follows_its_profile_clipped_and_rate_limited(external, tmp_path):
    art = external[0.05]
    signal = {"kind": "sweep", "low": 0.0, "high": 1.2, "rate": 0.2, "start": 1.0}
    data = {"artifact": "unused.json", "transport": {}, "plant": {"kind": "tank", "step": 0.005}, "duration": 20.0,
            "initial_state": {"q": 0.08, "h": 0.04}, "schedule_signal": {"load": signal}}  # fmt: skip
    res = gainlink.hil.run(data, artifact=art, report=tmp_path / "rep", plots=False)
    tr, sch = res.trace, res.metrics["schedule"]
    # the law's sigma, by hand: the profile clipped into [0.04, 1], then at most Ts * rate_max per step
    s = np.clip(1.2 - np.abs(1.2 - np.clip(0.2 * (tr.t - 1.0), 0.0, 2.4)), 0.04, 1.0)  # up to 1.2, back to 0
    want = [s[0]]
    for c in s[1:]:
        want.append(want[-1] + np.clip(c - want[-1], -art.Ts * 0.05, art.Ts * 0.05))
    assert np.allclose(tr.sigma, want, rtol=0, atol=1e-6)  # the C in float32
    assert sch["source"] == "external" and sch["clipped_steps"] > 0 and sch["rate_limited_steps"] > 300
    assert sch["max_rate"] <= 0.05 * (1 + 1e-4) and sch["held_steps"] == 0
    rows = (tmp_path / "rep" / "sigma.csv").read_text().splitlines()
    assert rows[0] == "t,sigma,held,clipped,rate" and len(rows) == 401 and rows[1].endswith(",0,1,0")
    assert "sigma load (external): covered [0.04, " in (tmp_path / "rep" / "summary.txt").read_text()


@pytest.mark.parametrize(
    "which, change, words",
    [
        ("external", {}, "the artifact is scheduled on load: give [schedule_signal.NAME]"),
        ("output", {"schedule_signal": {"load": 0.5}}, "schedule_signal.load is not an external scheduling signal"),
        ("output", {"controller": "qemu"}, 'controller = "qemu" serves the image\'s UART: give it a [transport]'),
        (
            "single",
            {"schedule_signal": {"load": 0.5}},
            "schedule_signal.load is not an external scheduling signal of the artifact (external: none)",
        ),
        ("external", {"schedule_signal": {"load": {"kind": "sweep", "low": 0.0}}}, "a sweep needs low, high and"),
    ],
)
def test_a_wrong_scheduling_signal_is_one_line(tank, singles, external, which, change, words):
    art = {"external": external[None], "output": tank, "single": singles[0]}[which]
    with pytest.raises(ScenarioError, match=None) as exc:
        run_scenario(_scenario(1.0, 0.04, 0.04, **change), artifact=art)
    assert words in str(exc.value) and "\n" not in str(exc.value)


SCENARIO = """\
name = "tank_sweep"
artifact = "gains.json"
duration = 6.0
controller = "reference"
[plant]
kind = "tank"
step = 0.005
[transport]
interface = "virtual"
[initial_state]
q = 0.08
h = 0.04
[reference.r_h]
kind = "sweep"
low = 0.04
high = 0.3
rate = 0.1
"""


def test_gainlink_hil_run_runs_a_scheduled_artifact_over_can_and_refuses_a_bad_signal_in_one_line(tank, tmp_path):
    tank.save(tmp_path / "gains.json")
    argv = ("--artifact", tmp_path / "gains.json", "--report", tmp_path / "rep", "--no-progress", "--no-plots")
    # The built-in sweep (the firmware's CAN node over the bus) on a udp port of this test's own
    sweep = read_toml(resolve_scenario_path("tank_sweep"), what="scenario", error=ValueError)[0]
    sweep["transport"] = udp_transport(fd=False)
    write_scenario(tmp_path / "tank_sweep.toml", sweep)
    res = run_cli("hil", "run", tmp_path / "tank_sweep.toml", *argv)
    assert res.code == 0, res.err
    assert "transport udp_multicast" in res.out and "sigma h (output): covered [0.04, " in res.out
    report = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert report["schedule"]["coverage"] > 0.95 and report["run"]["controller"]["kind"].startswith("firmware")
    assert "law=scheduled-float32" in report["run"]["controller"]["ready"] and report["lost"] == 0
    assert report["twin"]["worst_du_rel"] < 1e-5 and not report["model_twin"]["warning"]
    assert (tmp_path / "rep" / "sigma.csv").is_file()
    (tmp_path / "s.toml").write_text(SCENARIO)
    (tmp_path / "bad.toml").write_text(SCENARIO + '[schedule_signal.load]\nkind = "constant"\nvalue = 0.5\n')
    argv = ("hil", "run", tmp_path / "bad.toml", "--report", tmp_path / "rep2", "--no-progress")
    assert_refused(argv, "schedule_signal.load is not", tmp_path)
