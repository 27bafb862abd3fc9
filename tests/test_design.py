"""Design results checked against independent computations (SciPy's Riccati solvers, not python-control)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from gainlink.errors import DesignError
from gainlink.laws import design as design_spec
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import load_spec, parse_spec
from gainlink.synthesis.loop import poles_match
from support.cli import run_cli
from support.paths import EXAMPLES


def dlqr_scipy(A, B, Q, R):
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    return np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)


def kalman_predictor_scipy(Ad, Cd, W, V):
    P = scipy.linalg.solve_discrete_are(Ad.T, Cd.T, W, V)
    return Ad @ P @ Cd.T @ np.linalg.inv(Cd @ P @ Cd.T + V)


def test_seed_continuous_lqr_gain_is_the_corrected_one():
    # The seed's printed K (-3.162, -4.327, -52.40, -10.74) is wrong for its own plant and weights.
    spec = load_spec(EXAMPLES / "pendulum.toml")
    Q, R = np.diag([10.0, 1.0, 100.0, 1.0]), np.eye(1)
    P = scipy.linalg.solve_continuous_are(spec.plant.A, spec.plant.B, Q, R)
    K = np.linalg.solve(R, spec.plant.B.T @ P)
    np.testing.assert_allclose(K[0], [-3.1623, -4.4248, -39.608, -8.4795], atol=6e-4)
    assert not np.allclose(K[0], [-3.162, -4.327, -52.40, -10.74], atol=0.05)
    # The open-loop plant has the seed's unstable pole at +4.646 rad/s.
    assert np.max(np.linalg.eigvals(spec.plant.A).real) == pytest.approx(4.6457, abs=1e-3)


def test_pendulum_gains_match_independent_dlqr_and_kalman(example_artifacts):
    a = artifact_mod.load(example_artifacts["pendulum"])
    plant = a.data["plant"]
    A, B, C, D = (np.array(plant[k]) for k in "ABCD")
    Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete((A, B, C, D), a.Ts, method="zoh")
    np.testing.assert_allclose(a.Ad, Ad, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(a.Bd, Bd, rtol=1e-12, atol=1e-14)
    # LQI: DLQR on the plant augmented with z+ = z - Ts Ci y, with the recorded (augmented) Q and R.
    q, n = a.q, a.n
    Aa = np.block([[Ad, np.zeros((n, q))], [-a.Ts * a.Ci @ Cd, np.eye(q)]])
    Ba = np.vstack([Bd, -a.Ts * a.Ci @ Dd])
    ctl = a.data["design"]["controller"]
    Ka = dlqr_scipy(Aa, Ba, np.array(ctl["Q"]), np.array(ctl["R"]))
    np.testing.assert_allclose(a.K, Ka[:, :n], rtol=1e-9)
    np.testing.assert_allclose(a.Ki, Ka[:, n:], rtol=1e-9)
    obs = a.data["design"]["observer"]
    L = kalman_predictor_scipy(Ad, Cd, np.array(obs["W"]), np.array(obs["V"]))
    # Relative to the gain's norm: entries 1e-5 of the largest differ between SLICOT and SciPy in the 9th digit.
    assert np.linalg.norm(a.L - L) <= 1e-9 * np.linalg.norm(L)
    # The recorded Q is the spec's weights with the integrator weight appended.
    np.testing.assert_allclose(np.diag(ctl["Q"]), [10, 1, 100, 1, 5])


def test_combined_closed_loop_is_the_union_of_controller_and_observer(example_artifacts):
    for path in example_artifacts.values():
        a = artifact_mod.load(path)
        n, q = a.n, a.q
        # Simulate-free check: build [x; xh; z] dynamics directly from the law with r = 0.
        N = 2 * n + q
        Acl = np.zeros((N, N))
        for j in range(N):
            e = np.zeros(N)
            e[j] = 1.0
            x, xh, z = e[:n], e[n : 2 * n], e[2 * n :]
            u = -a.K @ xh - a.Ki @ z
            y = a.Cd @ x + a.Dd @ u
            Acl[:, j] = np.concatenate(
                [a.Ad @ x + a.Bd @ u, a.Ad @ xh + a.Bd @ u + a.L @ (y - a.Cd @ xh - a.Dd @ u), z - a.Ts * a.Ci @ y]
            )
        cl = np.linalg.eigvals(Acl)
        Aa = np.block([[a.Ad, np.zeros((n, q))], [-a.Ts * a.Ci @ a.Cd, np.eye(q)]])
        Ba = np.vstack([a.Bd, -a.Ts * a.Ci @ a.Dd])
        ctrl = np.linalg.eigvals(Aa - Ba @ np.hstack([a.K, a.Ki]))
        obs = np.linalg.eigvals(a.Ad - a.L @ a.Cd)
        assert np.max(np.abs(cl)) < 1
        assert poles_match(cl, np.concatenate([ctrl, obs]))
        recorded = np.array([complex(*z) for z in a.data["checks"]["closed_loop_poles"]])
        assert poles_match(recorded, cl)


def test_gains_recompute_from_the_file_alone(example_artifacts):
    # Everything needed is in gains.json: quadrotor uses Bryson's rule, recorded as the Q actually used.
    a = artifact_mod.load(example_artifacts["quadrotor_lateral"])
    ctl = a.data["design"]["controller"]
    np.testing.assert_allclose(np.diag(ctl["Q"])[:4], 1 / np.array([0.35, 2.0, 2.0, 0.5]) ** 2)
    np.testing.assert_allclose(ctl["R"], [[1 / 0.2**2]])
    Aa = np.block([[a.Ad, np.zeros((a.n, a.q))], [-a.Ts * a.Ci @ a.Cd, np.eye(a.q)]])
    Ba = np.vstack([a.Bd, -a.Ts * a.Ci @ a.Dd])
    Ka = dlqr_scipy(Aa, Ba, np.array(ctl["Q"]), np.array(ctl["R"]))
    np.testing.assert_allclose(np.hstack([a.K, a.Ki]), Ka, rtol=1e-9)


def test_wood_berry_is_mimo_with_a_fully_populated_gain(example_artifacts):
    a = artifact_mod.load(example_artifacts["wood_berry"])
    assert (a.m, a.p, a.q) == (2, 2, 2)
    assert np.all(np.abs(a.K) > 1e-6), a.K
    assert np.all(np.abs(a.Ki) > 1e-6), a.Ki
    # Four delays with first-order Pade: more states than the 4 delay-free lags.
    assert a.n > 4
    # The static gain of the realisation is the Wood-Berry steady-state gain matrix.
    A, B, C, D = (np.array(a.data["plant"][k]) for k in "ABCD")
    np.testing.assert_allclose(D - C @ np.linalg.solve(A, B), [[12.8, -18.9], [6.6, -19.4]], rtol=1e-9)


def test_pade_order_is_configurable():
    spec = load_spec(EXAMPLES / "wood_berry.toml")
    import tomllib

    data = tomllib.loads((EXAMPLES / "wood_berry.toml").read_text())
    data["plant"]["pade_order"] = spec.plant.pade_order + 1
    spec2 = parse_spec(data)
    assert spec2.plant.n > spec.plant.n
    z = np.linalg.eigvals(spec2.plant.A)
    assert np.all(z.real < 0)


def _small_spec(**overrides) -> dict:
    data = {
        "name": "servo",
        "Ts": 0.01,
        "plant": {"kind": "continuous", "A": [[0.0, 1.0], [0.0, -2.0]], "B": [[0.0], [4.0]], "C": [[1.0, 0.0]]},
        "controller": {"method": "lqr", "Q_diag": [10.0, 0.1], "R_diag": [1.0]},
        "observer": {"method": "kalman", "W_diag": [1e-4, 1e-2], "V_diag": [1e-4]},
        "limits": {"u_min": [-5.0], "u_max": [5.0]},
    }
    for key, value in overrides.items():
        data[key] = value
    return data


def test_pole_placement_and_luenberger_put_poles_where_asked():
    spec = parse_spec(
        _small_spec(
            controller={"method": "place", "poles": [-8.0, -9.0]},
            observer={"method": "luenberger", "poles": [[-30.0, 5.0], [-30.0, -5.0]], "form": "current"},
        )
    )
    r = design_spec(spec)
    a = artifact_mod.from_dict(r.artifact)
    want_c = np.exp(np.array([-8.0, -9.0]) * 0.01)
    want_o = np.exp(np.array([-30 + 5j, -30 - 5j]) * 0.01)
    assert poles_match(np.linalg.eigvals(a.Ad - a.Bd @ a.K), want_c)
    assert poles_match(np.linalg.eigvals(a.Ad - a.L @ a.Cd), want_o)
    np.testing.assert_allclose(a.L, a.Ad @ a.M, rtol=1e-12)


def _tampered(data: dict, change) -> dict:
    out = json.loads(json.dumps(data))
    change(out)
    return artifact_mod.seal(out)  # a consistent hash: only the invariant under test is broken


def _drop(*keys):
    return lambda d: [d.pop(k) for k in keys]


@pytest.mark.parametrize(
    "form, change, words",
    [
        ("current", _drop("M"), "observer_form 'current' needs the filter gain M"),
        ("current", lambda d: d.update(L=[[v * 1.01 for v in row] for row in d["L"]]), "requires L = Ad M"),
        ("current", lambda d: d.update(Dd=[[0.5]]), "requires Dd = 0"),
        ("predictor", lambda d: d.update(M=d["L"]), "M is only used with observer_form 'current'"),
        ("integral", _drop("Kaw"), "integral action (q=1) needs Kaw"),
        ("predictor", lambda d: d.update(Ci=[[1.0]]), "Ci given but q = 0"),
        ("predictor", lambda d: d.update(u_min=[6.0]), "u_min > u_max"),
    ],
)
def test_an_artifact_breaking_an_invariant_of_the_law_is_refused(form, change, words):
    """Each invariant the C relies on, broken in an otherwise valid (re-sealed) artifact, is one clear error."""
    observer = {
        "method": "kalman",
        "W_diag": [1e-4, 1e-2],
        "V_diag": [1e-4],
        "form": "current" if form == "current" else "predictor",
    }
    spec = _small_spec(observer=observer)
    if form == "integral":
        spec["plant"]["outputs"] = ["pos"]
        spec["integral"] = {"outputs": ["pos"], "Q_diag": [5.0]}
    data = design_spec(parse_spec(spec)).artifact
    artifact_mod.from_dict(data)  # the untouched one is valid
    with pytest.raises(artifact_mod.ArtifactError, match=re.escape(words)):
        artifact_mod.from_dict(_tampered(data, change))


def test_a_schema_violation_is_refused_after_the_same_artifact_passed_and_before_it_passes_again():
    """The schema's verdict is remembered by content (a design validates its artifact three times): an artifact
    edited after passing, even the same dict in place, is checked again, and the untouched one still passes."""
    data = design_spec(parse_spec(_small_spec())).artifact
    artifact_mod.from_dict(data)
    bad = json.loads(json.dumps(data))
    bad["anti_windup"] = "sometimes"
    with pytest.raises(artifact_mod.ArtifactError, match="does not match the schema at anti_windup"):
        artifact_mod.from_dict(bad, check_hash=False)
    saved = data["observer_form"]
    data["observer_form"] = "both"
    with pytest.raises(artifact_mod.ArtifactError, match="does not match the schema at observer_form"):
        artifact_mod.from_dict(data, check_hash=False)
    data["observer_form"] = saved
    assert artifact_mod.from_dict(data).sha256 == data["sha256"]


def test_ackermann_matches_place_for_single_input():
    r1 = design_spec(parse_spec(_small_spec(controller={"method": "place", "poles": [-8.0, -9.0]})))
    r2 = design_spec(parse_spec(_small_spec(controller={"method": "ackermann", "poles": [-8.0, -9.0]})))
    np.testing.assert_allclose(r1.artifact["K"], r2.artifact["K"], rtol=1e-8)
    assert any("Ackermann" in w for w in r2.warnings)


def test_tustin_gives_the_bilinear_plant():
    r = design_spec(parse_spec(_small_spec(discretization="tustin")))
    a = artifact_mod.from_dict(r.artifact)
    A, B, C, D = np.array([[0.0, 1.0], [0.0, -2.0]]), np.array([[0.0], [4.0]]), np.array([[1.0, 0.0]]), np.zeros((1, 1))
    Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete((A, B, C, D), 0.01, method="bilinear")
    np.testing.assert_allclose(a.Ad, Ad, rtol=1e-10)
    # Tustin's realisation differs by a state scaling between libraries; compare the transfer function.
    H = lambda Ad, Bd, Cd, Dd, z: (Cd @ np.linalg.solve(z * np.eye(2) - Ad, Bd) + Dd)[0, 0]  # noqa: E731
    for z in (0.5, 1.5j, -0.3 + 0.2j):
        assert H(a.Ad, a.Bd, a.Cd, a.Dd, z) == pytest.approx(H(Ad, Bd, Cd, Dd, z), rel=1e-9)
    assert a.data["design"]["discretization"] == "tustin"


def test_design_is_deterministic_byte_for_byte(tmp_path):
    for d in ("a", "b"):
        assert run_cli("design", EXAMPLES / "pendulum.toml", "--out", tmp_path / d).code == 0
    first, second = (tmp_path / d / "gains.json" for d in ("a", "b"))
    assert first.read_bytes() == second.read_bytes()
    data = json.loads(first.read_text())
    assert "time" not in json.dumps(data).lower()
    assert data["provenance"]["spec_sha256"]
    assert data["sha256"] == artifact_mod.content_sha256(data)


def _stiff_spec(integral_weight: float) -> dict:
    """A stiff two-mass plant (1000 rad/s coupling) at 1 kHz with integral action weighted ``integral_weight``."""
    return {
        "name": "stiff",
        "Ts": 0.001,
        "plant": {
            "A": [[0, 1, 0, 0], [-1e6, -20, 1e6, 0], [0, 0, 0, 1], [1e5, 0, -1e5, -0.1]],
            "B": [[0], [1000.0], [0], [0]],
            "C": [[0, 0, 1, 0]],
        },
        "controller": {"Q_diag": [1, 1e-6, 1, 1e-3], "R_diag": [1.0]},
        "integral": {"outputs": [0], "Q_diag": [integral_weight]},
        "observer": {"W_diag": [1e-6] * 4, "V_diag": [1e-6]},
        "limits": {"u_min": [-100.0], "u_max": [100.0]},
        "implementation": {"float32_check": False},
    }


def test_badly_scaled_lqr_weights_are_solved_by_scaling_the_problem():
    """An integrator weighted 1e11 beside states weighted 1e-6 made SLICOT's DARE fail ('is (Q, A) detectable?');
    the scaled problem gives the gain SciPy's DARE computes for the unscaled one."""
    r = design_spec(parse_spec(_stiff_spec(1e11)))
    a = r.artifact
    Ad, Bd, Cd = (np.array(a[k]) for k in ("Ad", "Bd", "Cd"))
    Aa = np.block([[Ad, np.zeros((4, 1))], [-0.001 * Cd, np.eye(1)]])
    Ba = np.vstack([Bd, [[0.0]]])
    P = scipy.linalg.solve_discrete_are(Aa, Ba, np.diag([1, 1e-6, 1, 1e-3, 1e11]), np.eye(1))
    K = np.linalg.solve(np.eye(1) + Ba.T @ P @ Ba, Ba.T @ P @ Aa)
    np.testing.assert_allclose(np.hstack([a["K"], a["Ki"]]), K, rtol=1e-7)
    assert any("rescaled" in w for w in r.warnings)


def test_a_marginal_mode_the_weights_cannot_see_is_named():
    with pytest.raises(DesignError, match=r"mode at z = 1 \(mostly integral of y0\).*give it a weight in Q"):
        design_spec(parse_spec(_stiff_spec(0.0)))


@pytest.mark.parametrize(
    ("break_controller", "break_observer", "part"),
    [(True, False, "the controller with the plant"), (False, True, "the observer"), (True, True, "; and the observer")],
)
def test_given_gains_that_leave_the_loop_unstable_name_the_part_and_its_eigenvalue(
    break_controller, break_observer, part
):
    """K = 0 leaves the pendulum's unstable pole (exp(sqrt(21.582) Ts), from the continuous A) in A - B K; L = 0
    leaves it in A - L C."""
    import control

    spec = load_spec(EXAMPLES / "pendulum.toml")
    sysd = control.c2d(control.ss(spec.plant.A, spec.plant.B, spec.plant.C, 0), 0.01)
    K = np.zeros((1, 4)) if break_controller else control.dlqr(sysd.A, sysd.B, np.eye(4), np.eye(1))[0]
    L = np.zeros((4, 2)) if break_observer else control.place(sysd.A.T, sysd.C.T, [0.5, 0.55, 0.6, 0.65]).T
    data = {
        "name": "p", "Ts": 0.01,
        "plant": {"A": spec.plant.A.tolist(), "B": spec.plant.B.tolist(), "C": spec.plant.C.tolist()},
        "controller": {"method": "given", "K": K.tolist()},
        "observer": {"method": "given", "L": L.tolist()},
        "limits": {"u_min": [-20.0], "u_max": [20.0]},
    }  # fmt: skip
    unstable = np.exp(np.sqrt(21.582) * 0.01)
    with pytest.raises(DesignError) as err:
        design_spec(parse_spec(data))
    msg = str(err.value)
    assert part in msg
    assert f"|z| = {unstable:.6g}" in msg
    if not break_observer:
        assert "the observer" not in msg
    if not break_controller:
        assert "controller with the plant" not in msg
