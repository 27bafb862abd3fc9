"""The showcase's step figures and summary (``gainlink hil showcase``) on traces whose answers are known by hand:
a first-order response settles into 5 % of its step at tau ln 20; a limit cycle wider than the band has not
settled, whatever its phase at the run's last sample; the summary says so, and shows the start it leaves out."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from gainlink.hil.loop.showcase import step_metrics
from gainlink.hil.loop.showcase_report import showcase_summary

TS, AT, END = 0.05, 10.0, 25.0
STEP = {"from": 0.1, "to": 0.04, "at": AT, "duration": END}


def _run(y_after, y_before=0.1) -> SimpleNamespace:
    t = np.arange(0.0, END, TS)
    after = t >= AT
    y = np.where(after, y_after(t - AT), y_before)
    r = np.where(after, STEP["to"], STEP["from"])
    return SimpleNamespace(trace=SimpleNamespace(t=t, y=y[:, None], r=r[:, None]))


def test_a_first_order_response_settles_at_tau_ln_20():
    tau, size = 1.0, STEP["to"] - STEP["from"]
    m = step_metrics(_run(lambda s: STEP["to"] - size * np.exp(-(s + TS) / tau)), STEP)
    assert m["settled"] and abs(m["settling_time_s"] - tau * np.log(20.0)) <= TS
    assert m["overshoot_pct"] == 0.0 and m["start_max_abs_e"] == 0.0


def test_a_limit_cycle_inside_the_band_at_the_last_sample_has_not_settled():
    size = abs(STEP["to"] - STEP["from"])
    period = 0.5  # ten samples; amplitude twice the 5 % band, the last sample at a zero crossing (inside it)
    cycle = lambda s: STEP["to"] + 0.1 * size * np.sin(2 * np.pi * (s - (END - AT - TS)) / period)  # noqa: E731
    run = _run(cycle)
    assert abs(run.trace.y[-1, 0] - STEP["to"]) < 0.05 * size  # inside the band at the end
    m = step_metrics(run, STEP)
    assert not m["settled"] and m["settling_time_s"] is None


def test_the_summary_says_not_settled_and_shows_the_start_with_units():
    row = {
        "complete": True,
        "sweep_iae": 2.09,
        "sweep_max_abs_e": 0.1,
        "sweep_hold_max_abs_e": 0.02,
        "model_twin_worst": 0.119,
        "twin_worst_du_rel": 1.8e-5,
        "start_max_abs_e": 0.373,
        "start_worst_run": "step_low",
        "step_low": {"overshoot_pct": 17.3, "settling_time_s": None, "settled": False, "start_max_abs_e": 0.373},
    }
    sched = dict(row, start_max_abs_e=0.004, step_low={**row["step_low"], "settling_time_s": 1.5, "settled": True})
    doc = {"designs": {"single": row, "scheduled": sched}, "spec": "tank.toml", "single_point": 0.49,
           "sweep": {"start": AT}, "steps": {"low": STEP}}  # fmt: skip
    text = showcase_summary(json.loads(json.dumps(doc)), report_dir=Path("rep"))
    single = next(ln for ln in text.splitlines() if ln.strip().startswith("single "))
    assert "not settled" in single and "15 s" not in single
    assert "0.373 m" in single and "2.09 m s" in single and "17.3 %" in single and "0.119 of range" in single
    assert "1.5 s" in next(ln for ln in text.splitlines() if ln.strip().startswith("scheduled "))
    assert "the first 10 s of each run" in text and "single 0.373 m (in step_low)" in text
