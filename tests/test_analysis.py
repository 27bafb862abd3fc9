"""Analysis verdicts on plants whose structure is known by construction."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gainlink.laws import design
from gainlink.spec import parse_spec
from gainlink.synthesis.analysis import transmission_zeros
from gainlink.synthesis.plant_report import analyze as analyze_spec
from support.cli import run_cli
from support.paths import EXAMPLES


def analyze(parsed):
    """The analysis of a spec, designing it with its law (what gl.analyze does)."""
    return analyze_spec(parsed, design=design)


def spec(A, B, C, *, D=None, Ts=0.01, controller=None, observer=None):
    n, m, p = len(A), len(B[0]), len(C)
    plant = {"kind": "continuous", "A": A, "B": B, "C": C}
    if D is not None:
        plant["D"] = D
    return parse_spec(
        {
            "name": "probe",
            "Ts": Ts,
            "plant": plant,
            "controller": controller or {"method": "lqr", "Q_diag": [1.0] * n, "R_diag": [1.0] * m},
            "observer": observer or {"method": "kalman", "W_diag": [0.01] * n, "V_diag": [0.01] * p},
            "limits": {"u_min": [-1.0] * m, "u_max": [1.0] * m},
        }
    )


def test_pbh_names_the_uncontrollable_and_unobservable_modes():
    # Diagonal plant: mode -3 has no input, mode -5 no sensor; both stable, so the plant stays stabilizable.
    rep = analyze(spec([[1.0, 0, 0], [0, -3.0, 0], [0, 0, -5.0]], [[1.0], [0.0], [1.0]], [[1.0, 1.0, 0.0]]))
    verdict = {round(md.eigenvalue.real, 6): md for md in rep.modes}
    assert not verdict[-3.0].controllable and verdict[-3.0].observable
    assert verdict[-5.0].controllable and not verdict[-5.0].observable
    assert verdict[1.0].controllable and verdict[1.0].observable and not verdict[1.0].stable
    assert rep.controllability_rank == 2 and rep.observability_rank == 2
    assert rep.stabilizable and rep.detectable
    assert any("mode -3 is uncontrollable (stable)" in w for w in rep.warnings)
    assert any("mode -5 is unobservable (stable)" in w for w in rep.warnings)


def test_unstable_uncontrollable_mode_makes_the_plant_unstabilizable():
    rep = analyze(spec([[2.0, 0], [0, -1.0]], [[0.0], [1.0]], [[1.0, 1.0]]))
    assert not rep.stabilizable
    assert any("mode 2 is uncontrollable (UNSTABLE)" in w for w in rep.warnings)
    assert any("design of this spec fails" in w for w in rep.warnings)


def test_transmission_zeros_and_nonminimum_phase_warning():
    # G(s) = (s - 2) / ((s + 1)(s + 3)) in controllable canonical form: one RHP zero at +2.
    rep = analyze(spec([[0.0, 1.0], [-3.0, -4.0]], [[0.0], [1.0]], [[-2.0, 1.0]]))
    assert len(rep.transmission_zeros) == 1
    assert rep.transmission_zeros[0] == pytest.approx(2.0)
    assert rep.nonminimum_phase_zeros and any("non-minimum-phase" in w for w in rep.warnings)


def test_zeros_of_a_non_square_plant():
    A = np.diag([-1.0, -2.0, -3.0])
    B = np.array([[1.0], [1.0], [1.0]])
    C = np.array([[1.0, -2.0, 0.0], [1.0, -2.0, 0.0]])  # both outputs are -s/((s+1)(s+2)): common zero at 0
    z = transmission_zeros(A, B, C, np.zeros((2, 1)))
    assert np.min(np.abs(z)) == pytest.approx(0.0, abs=1e-9)


def test_slow_sampling_is_flagged_against_the_closed_loop_bandwidth():
    fast = analyze(spec([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], Ts=0.01))
    # the crossover is that of the loop broken at the actuator with the observer in it (design's margins)
    slow = analyze(
        spec(
            [[0.0, 1.0], [0.0, 0.0]],
            [[0.0], [1.0]],
            [[1.0, 0.0]],
            Ts=1.0,
            controller={"method": "lqr", "Q_diag": [100.0, 1.0], "R_diag": [0.01]},
        )
    )
    assert fast.sample_rate_ratio >= 10 and not any("sample rate" in w for w in fast.warnings)
    assert slow.sample_rate_ratio < 10 and any("sample rate is only" in w for w in slow.warnings)


def test_badly_scaled_states_are_named():
    # State 1 in micrometres, state 0 in metres: a 1e6 coupling.
    rep = analyze(spec([[0.0, 1e-6], [-1e6, -1.0]], [[0.0], [1e6]], [[1.0, 0.0]]))
    assert rep.badly_scaled_states
    assert any("badly scaled" in w for w in rep.warnings)
    ok = analyze(spec([[0.0, 1.0], [-1.0, -1.0]], [[0.0], [1.0]], [[1.0, 0.0]]))
    assert not ok.badly_scaled_states


def test_analyze_cli_json_for_the_examples():
    for name in ("pendulum", "quadrotor_lateral", "wood_berry"):
        res = run_cli("analyze", EXAMPLES / f"{name}.toml", "--json")
        assert res.code == 0, res.err
        rep = json.loads(res.out)
        assert rep["stabilizable"] and rep["detectable"]
        assert rep["sample_rate_ratio"] >= 10
    rep = json.loads(run_cli("analyze", EXAMPLES / "pendulum.toml", "--json").out)
    assert max(z[0] for z in rep["open_loop_poles"]) == pytest.approx(4.6457, abs=1e-3)
    wb = json.loads(run_cli("analyze", EXAMPLES / "wood_berry.toml", "--json").out)
    assert wb["nonminimum_phase_zeros"]  # Pade dead time brings right-half-plane zeros
    text = run_cli("analyze", EXAMPLES / "pendulum.toml").out
    assert "PBH per mode" in text and "stabilizable" in text
