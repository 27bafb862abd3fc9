"""Injected faults in the HIL of a scheduled artifact over its link (gainlink.hil.loop.bridge): the tank of
examples/tank_scheduled.toml, scheduled on its measured level, through the real gainlink_can process on python-can
udp_multicast, with a window of NaN samples and a window of dropped samples. Oracle: the scheduled float32 model
(gainlink.laws.scheduled.model, bit for bit the C) fed the samples the node received, rebuilt here from the
scenario's windows (NaN rows in, dropped rows out): the same commands, sigma flags and refusals."""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import ScenarioError
from gainlink.hil import run as hil_run
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.shipping.artifact import from_dict
from schedule_cases import tank_dict, tank_hil_scenario
from support.designs import designed
from support.hil import udp_transport
from support.status import FAULT, SIGMA_BITS, scheduled_status

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")

NAN = (2.0, 2.3)  # s: the level's sample sent as NaN (sigma = h with it: the sample is refused, sigma held)
DROP = (3.0, 3.15)  # s: the sample's frames not sent


@pytest.fixture(scope="module")
def tank(tmp_path_factory):
    design = designed(tank_dict())
    a = from_dict(design)
    path = tmp_path_factory.mktemp("tank") / "tank.json"
    a.save(path)
    return a, path


def _scenario(path, **extra) -> dict:
    """The tank's level climbing 0.04 -> 1 m from t = 1 s, with a NaN window and a drop window."""
    faults = [{"kind": "nan", "start": NAN[0], "stop": NAN[1]}, {"kind": "drop", "start": DROP[0], "stop": DROP[1]}]
    data = {"transport": udp_transport(fd=False), "duration": 4.0, "faults": faults} | extra
    return tank_hil_scenario(path, name="tank_faults_can", **data)


def test_nan_and_dropped_samples_reach_the_node_as_the_model_is_fed_and_the_report_counts_them(tank, tmp_path):
    a, path = tank
    res = hil_run(_scenario(path), report=tmp_path / "report", plots=False)
    tr, m = res.trace, res.metrics
    t = tr.t
    nan = (t >= NAN[0]) & (t < NAN[1])
    drop = (t >= DROP[0]) & (t < DROP[1])
    assert res.complete and tr.t.size == 80 and nan.sum() == 6 and drop.sum() == 3
    assert m["faults_injected"] == {"drop": 3, "delay": 0, "duplicate": 0, "reorder": 0, "nan": 6}
    assert m["lost"] == 3 and not tr.got[drop].any() and tr.got[~drop].all()

    Y, R = tr.y.astype(np.float32).astype(np.float64), tr.r.astype(np.float32).astype(np.float64)
    Y[nan] = np.nan  # what the node received on those steps; the dropped ones it never saw
    keep = ~drop
    model = ScheduledFloat32Loop(a).run(Y[keep], R[keep])
    u = tr.u.astype(np.float32).view(np.uint32)
    np.testing.assert_array_equal(u[keep], model.u.astype(np.float32).view(np.uint32))
    np.testing.assert_array_equal(tr.flags[keep], scheduled_status(model.sigma_flags, model.fault))  # the node's
    first = int(np.flatnonzero(drop)[0])
    assert np.all(u[drop] == u[first - 1])  # a lost command holds the last one

    # sigma = h is a measured output: a NaN sample is refused whole (DESIGN.md, "Scheduled law"): the node answers
    # with its fault bit and u_op at the held sigma; sigma keeps its last valid value and no sigma flag is raised
    assert np.all(tr.flags[nan] & FAULT) and not np.any(tr.flags[keep & ~nan] & FAULT)
    assert m["refused_steps"] == 6
    assert np.all(tr.sigma[nan] == tr.sigma[int(np.flatnonzero(nan)[0]) - 1])
    assert not np.any(tr.flags[nan] & sum(SIGMA_BITS.values())) and m["schedule"]["held_steps"] == 0
    summary = (tmp_path / "report" / "summary.txt").read_text()
    assert "nan 6" in summary and "drop 3" in summary


def test_a_nan_fault_needs_float32_values_on_the_link(tank):
    _, path = tank
    transport = dict(udp_transport(fd=False), encoding="int16")
    with pytest.raises(ScenarioError, match='encoding = "float32"'):
        hil_run(_scenario(path, transport=transport))


def test_a_realtime_run_is_paced_reports_its_timing_and_the_node_runs_the_law_on_the_samples_sent(
    tank, tmp_path, realtime_alone
):
    a, path = tank
    res = hil_run(_scenario(path, mode="realtime", duration=2.5, faults=[]), report=tmp_path / "report", plots=False)
    tr, m = res.trace, res.metrics
    assert res.complete and tr.t.size == 50 and m["mode"] == "realtime" and m["period_s"] == a.Ts
    # the bridge's timing block (no values asserted: the machine is shared)
    assert set(m["period_jitter_us"]) == {"p50", "p99", "max"} and m["period_jitter_us"]["p99"] is not None
    assert m["overrun_policy"] == "skip" and isinstance(m["overruns"], int) and isinstance(m["sched_fifo"], bool)
    assert isinstance(m["pm_qos"], bool) and m["deadline_misses"] == m["lost"] >= m["overruns"]
    sent = np.isfinite(tr.tick_ns)  # ticks missed in a stall (overruns) sent nothing
    assert np.count_nonzero(~sent) == m["overruns"] and np.all(np.isfinite(tr.deadline_ns))
    assert np.all(np.diff(tr.deadline_ns) == pytest.approx(a.Ts * 1e9, abs=1.0))  # one tick per Ts
    Y, R = tr.y.astype(np.float32).astype(np.float64), tr.r.astype(np.float32).astype(np.float64)
    model = ScheduledFloat32Loop(a).run(Y[sent], R[sent])
    got = tr.got[sent]
    u = tr.u[sent].astype(np.float32).view(np.uint32)
    np.testing.assert_array_equal(u[got], model.u.astype(np.float32).view(np.uint32)[got])
    np.testing.assert_array_equal(tr.flags[sent][got], scheduled_status(model.sigma_flags, model.fault)[got])
    summary = (tmp_path / "report" / "summary.txt").read_text()
    assert "period jitter us" in summary and "overruns" in summary
