"""Designs against the exact sampled dead times (gainlink.synthesis.deadtime), checked against hand-derived models."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from gainlink.laws import design as design_spec
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import parse_spec
from gainlink.synthesis.deadtime import element_model
from support.cli import run_cli
from support.paths import EXAMPLES


def _step_response(sys, steps: int) -> np.ndarray:
    A, B, C, D = (np.asarray(M, float) for M in (sys.A, sys.B, sys.C, sys.D))
    x = np.zeros(A.shape[0])
    y = np.zeros(steps)
    for k in range(steps):
        y[k] = (C @ x + D[:, 0])[0]
        x = A @ x + B[:, 0]
    return y


@pytest.mark.parametrize("tau", [0.0, 0.4, 1.0, 2.5, 7.0])
def test_a_first_order_element_with_dead_time_samples_its_exact_step_response(tau):
    """K e^{-tau s}/(T s + 1) under a unit step held from t = 0: y(t) = K (1 - e^{-(t - tau)/T}) for t >= tau
    (the analytic response; a ZOH step input is exact), whole or fractional periods of delay."""
    K, T, Ts = 12.8, 16.7 / 5, 1.0
    y = _step_response(element_model([K], [T, 1.0], tau, Ts), 40)
    t = np.arange(40) * Ts
    want = np.where(t >= tau, K * (1 - np.exp(-np.clip(t - tau, 0, None) / T)), 0.0)
    np.testing.assert_allclose(y, want, atol=1e-12 * K)


def test_a_second_order_element_with_a_fractional_delay_matches_a_fine_simulation():
    """(s + 3) e^{-1.3 s} / (s^2 + 0.8 s + 4) (a direct feedthrough-free oscillator with a zero), Ts = 0.5:
    the sampled step response equals scipy's continuous response shifted by the delay."""
    import scipy.signal

    num, den, tau, Ts = [1.0, 3.0], [1.0, 0.8, 4.0], 1.3, 0.5
    y = _step_response(element_model(num, den, tau, Ts), 30)
    t = np.arange(30) * Ts
    fine = np.arange(0, 160) * 0.1  # t - tau falls on this grid (0.2, 0.7, 1.2, ...)
    _, yc = scipy.signal.step(scipy.signal.lti(num, den), T=fine)
    idx = np.rint(np.clip(t - tau, 0, None) / 0.1).astype(int)
    want = np.where(t >= tau, yc[idx], 0.0)
    np.testing.assert_allclose(y, want, atol=1e-9)


def _wood_berry(pade_order: int) -> dict:
    """The example spec with limits far away: the law stays linear, as the check assumes."""
    data = tomllib.loads((EXAMPLES / "wood_berry.toml").read_text())
    data["plant"]["pade_order"] = pade_order
    data["limits"].update(u_min=[-1e6, -1e6], u_max=[1e6, 1e6])
    return data


def _column_in_closed_loop(art, steps: int) -> np.ndarray:
    """The Wood-Berry column with its true dead times (whole minutes at Ts = 1 min), each element
    K e^{-d s}/(T s + 1) sampled exactly by hand: v+ = a v + K (1 - a) u[k - d], a = e^{-Ts/T}; the float64
    law closes the loop from a 1 mol % distillate offset (reference 0)."""
    K = np.array([[12.8, -18.9], [6.6, -19.4]])
    T = np.array([[16.7, 21.0], [10.9, 14.4]])
    d = np.array([[1, 3], [7, 3]])
    a = np.exp(-1.0 / T)
    v = np.zeros((2, 2))
    past_u = np.zeros((steps + 8, 2))
    law = ReferenceLoop(art)
    Y = np.zeros((steps, 2))
    for k in range(steps):
        y = v.sum(axis=1) + np.array([1.0, 0.0])
        Y[k] = y
        u = law.step(y, np.zeros(2)).u
        past_u[k + 8] = u
        for i in range(2):
            for j in range(2):
                v[i, j] = a[i, j] * v[i, j] + K[i, j] * (1 - a[i, j]) * past_u[k + 8 - d[i, j], j]
    return Y


@pytest.mark.parametrize("pade_order, stable", [(1, False), (2, True)])
def test_the_dead_time_check_agrees_with_the_column_simulated_by_hand(pade_order, stable):
    """Designed with first-order Padé the Wood-Berry LQI is unstable on the column with its true dead times
    (the check says so and design warns); with second order it is stable. The oracle is the hand-sampled
    column in closed loop with the float64 law: its error dies out or grows over 1500 min."""
    result = design_spec(parse_spec(_wood_berry(pade_order)))
    check = result.artifact["checks"]["dead_time"]
    assert check["stable"] is stable and check["pade_order"] == pade_order
    assert any("true dead times" in w for w in result.warnings) is not stable
    Y = _column_in_closed_loop(artifact_mod.from_dict(result.artifact), 1500)
    late, early = np.max(np.abs(Y[1200:])), np.max(np.abs(Y[:300]))
    assert bool(late < 1e-3 * early) is stable and bool(late > 1e3 * early) is not stable
    if not stable:  # the growth per step of the simulated column is the check's spectral radius
        growth = (np.max(np.abs(Y[600:900])) / np.max(np.abs(Y[300:600]))) ** (1 / 300)
        assert growth == pytest.approx(check["spectral_radius"], rel=2e-3)


def test_the_example_is_stable_on_its_true_dead_times_and_analyze_reports_it():
    res = run_cli("analyze", EXAMPLES / "wood_berry.toml")
    assert res.code == 0, res.err
    assert "with the exact dead times (design: Padé order 2): closed-loop spectral radius" in res.out
    assert "-> stable" in res.out.split("with the exact dead times")[1].splitlines()[0]


def test_specs_without_dead_time_carry_no_dead_time_check():
    data = _wood_berry(2)
    data["plant"]["delay"] = [[0.0, 0.0], [0.0, 0.0]]
    assert "dead_time" not in design_spec(parse_spec(data)).artifact["checks"]
