"""Hypothesis properties of the law and the design."""

from __future__ import annotations

import functools

import numpy as np
from gainlink.errors import DesignError
from gainlink.laws import design as design_spec
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import parse_spec
from gainlink.synthesis.discretize import Discretised
from gainlink.synthesis.loop import check_separation, closed_loop_matrix, poles_match
from gainlink.synthesis.random_plants import random_spec
from hypothesis import given, reject, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

PROPERTY_SETTINGS = settings(max_examples=40, deadline=None, derandomize=True)


@functools.cache
def _artifacts():
    """The four designs the properties draw from: made on first use, not at import (every xdist worker imports
    this module to collect it; only the one running these tests needs them)."""
    specs = [
        random_spec(11, n=3, m=1, p=1, q=1, anti_windup="none"),
        random_spec(12, n=4, m=2, p=2, q=2, form="current", anti_windup="clamp"),
        random_spec(13, n=5, m=2, p=3, q=1, anti_windup="backcalc", feedthrough=True),
        random_spec(14, n=4, m=3, p=2, q=0),
    ]
    return [artifact_mod.from_dict(design_spec(parse_spec(s)).artifact) for s in specs]


@PROPERTY_SETTINGS
@given(data=st.data())
def test_commands_stay_within_limits_and_finite_for_any_finite_input(data):
    a = _artifacts()[data.draw(st.integers(0, len(_artifacts()) - 1), label="artifact")]
    N = data.draw(st.integers(1, 150), label="steps")
    finite = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)
    Y = data.draw(arrays(np.float64, (N, a.p), elements=finite), label="Y")
    R = data.draw(arrays(np.float64, (N, a.q), elements=finite), label="R")
    trace = ReferenceLoop(a).run(Y, R)
    assert np.all(trace.u >= a.u_min) and np.all(trace.u <= a.u_max)
    assert np.all(np.isfinite(trace.u)) and np.all(np.isfinite(trace.xh)) and np.all(np.isfinite(trace.z))
    assert not trace.fault.any()


@PROPERTY_SETTINGS
@given(data=st.data())
def test_non_finite_samples_never_propagate(data):
    a = _artifacts()[data.draw(st.integers(0, len(_artifacts()) - 1), label="artifact")]
    N = data.draw(st.integers(1, 60), label="steps")
    bounded = st.one_of(st.floats(-1e4, 1e4), st.sampled_from([np.nan, np.inf, -np.inf]))
    Y = data.draw(arrays(np.float64, (N, a.p), elements=bounded), label="Y")
    R = data.draw(arrays(np.float64, (N, a.q), elements=bounded), label="R")
    trace = ReferenceLoop(a).run(Y, R)
    bad = ~(np.isfinite(Y).all(axis=1) & np.isfinite(R).all(axis=1))
    np.testing.assert_array_equal(trace.fault, bad)
    assert np.all(np.isfinite(trace.u)) and np.all(np.isfinite(trace.xh)) and np.all(np.isfinite(trace.z))
    safe = np.clip(np.zeros(a.m), a.u_min, a.u_max)
    assert np.all(trace.u[bad] == safe)


@PROPERTY_SETTINGS
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(1, 6),
    m=st.integers(1, 3),
    p=st.integers(1, 3),
    q=st.integers(0, 3),
    aw=st.sampled_from(["none", "clamp", "backcalc"]),
)
def test_predictor_and_current_forms_give_the_same_closed_loop(seed, n, m, p, q, aw):
    q = min(q, m, p)
    results = {}
    for form in ("predictor", "current"):
        spec = random_spec(seed, n=n, m=m, p=p, q=q, form=form, anti_windup=aw)
        spec["implementation"] = {"float32_check": False}  # gains and poles only: skip the closed-loop runs
        try:
            results[form] = design_spec(parse_spec(spec))
        except DesignError:
            reject()  # an infeasible draw (e.g. two integrators on a one-state plant), whichever the form
    pred, cur = (artifact_mod.from_dict(results[f].artifact) for f in ("predictor", "current"))
    np.testing.assert_allclose(pred.K, cur.K, rtol=1e-12)
    np.testing.assert_allclose(pred.L, cur.L, rtol=1e-9, atol=1e-12)
    d = Discretised(A=cur.Ad, B=cur.Bd, C=cur.Cd, D=cur.Dd, method="zoh", Ts=cur.Ts)
    Aa = np.block([[cur.Ad, np.zeros((n, q))], [-cur.Ts * cur.Ci @ cur.Cd, np.eye(q)]])
    Ba = np.vstack([cur.Bd, np.zeros((q, m))])
    A_ctrl, A_obs = Aa - Ba @ np.hstack([cur.K, cur.Ki]), cur.Ad - cur.L @ cur.Cd
    for form, art in (("predictor", pred), ("current", cur)):
        Acl = closed_loop_matrix(d, K=art.K, Ki=art.Ki, L=art.L, M=art.M, Ci=art.Ci, Ts=art.Ts, form=form)
        check_separation(Acl, A_ctrl, A_obs)  # raises if the loop is anything but controller + observer
    assert poles_match(results["predictor"].closed_loop_poles, results["current"].closed_loop_poles, tol=1e-5)
