"""The Python API (``import gainlink as gl``): designs from python-control systems, artifacts from the
user's own gains with every design check, the law as python-control systems, and the docstring examples.

Oracles are independent of gainlink: SciPy's discrete Riccati solver, python-control's margins and
responses, and closed loops written out in the tests from the law's equations.
"""

from __future__ import annotations

import doctest
import json
import os
import runpy
import stat
import subprocess
import sys

import control as ct
import gainlink as gl
import numpy as np
import pytest
import scipy.linalg
from gainlink.errors import DesignError, SpecError
from support.cli import assert_refused, run_cli
from support.paths import EXAMPLES, ROOT


def _double_integrator() -> ct.StateSpace:
    return ct.ss(
        [[0.0, 1.0], [0.0, 0.0]],
        [[0.0], [1.0]],
        [[1.0, 0.0]],
        [[0.0]],
        states=["pos", "vel"],
        inputs=["force"],
        outputs=["pos"],
    )


def test_curated_namespace_lists_what_a_user_needs():
    assert {"design", "from_gains", "load", "replay", "simulate", "Artifact", "hil"} <= set(gl.__all__)
    assert all(hasattr(gl, name) for name in gl.__all__)
    assert callable(gl.design) and callable(gl.hil.run)


def test_campaigns_are_in_the_namespace_without_import_gainlink_loading_dask():
    # A fresh interpreter: this one may have imported Dask for other tests.
    code = (
        "import sys, gainlink as gl\n"
        "assert 'campaign' in gl.__all__\n"
        "assert not {'dask', 'distributed', 'gainlink.hil.campaign'} & set(sys.modules), 'imported eagerly'\n"
        "import gainlink.hil.campaign as c\n"
        "assert gl.campaign is c and gl.campaign.run is c.runner.run\n"
        "from gainlink import campaign\n"
        "assert campaign is c\n"
        "try:\n    gl.no_such_thing\nexcept AttributeError as e:\n    print(e)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "module 'gainlink' has no attribute 'no_such_thing'"


@pytest.mark.parametrize(
    "module",
    [
        "gainlink.api",
        "gainlink.hil",
        "gainlink.proof.onestep",
        "gainlink.proof.twin",
        "gainlink.laws.lq.fidelity",
        "gainlink.synthesis.compensator",
    ],
)
def test_docstring_examples_run(module):
    import importlib

    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0


def test_design_from_a_continuous_statespace_equals_scipy_dlqr():
    Q, R = np.diag([10.0, 1.0]), np.array([[0.5]])
    art = gl.design(
        _double_integrator(), Ts=0.02, Q=Q, R=R, W=np.diag([1e-4, 1e-3]), V=[[1e-5]], u_min=[-3.0], u_max=[3.0]
    )
    # independent oracle: ZOH by the matrix exponential, DARE by SciPy
    Phi = scipy.linalg.expm(
        np.block([[np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])], [np.zeros((1, 3))]]) * 0.02
    )
    Ad, Bd = Phi[:2, :2], Phi[:2, 2:]
    P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R)
    K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
    np.testing.assert_allclose(art.K, K, rtol=1e-9)
    assert art.signals["states"] == ["pos", "vel"] and art.signals["inputs"] == ["force"]
    assert art.provenance["gains"] == "designed"


def test_design_from_a_discrete_transfer_function_takes_its_sample_time():
    G = ct.tf([0.1], [1.0, -0.9], 0.05)
    art = gl.design(G, Q=[[1.0]], R=[[1.0]], W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    assert art.Ts == 0.05 and (art.n, art.m, art.p) == (1, 1, 1)
    with pytest.raises(SpecError, match="differs from the discrete system's dt"):
        gl.design(G, Ts=0.01, Q=[[1.0]], R=[[1.0]], W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    with pytest.raises(SpecError, match="continuous plant needs Ts"):
        gl.design(_double_integrator(), Q=np.eye(2), R=[[1.0]], W=np.eye(2), V=[[1.0]], u_min=[-1.0], u_max=[1.0])


def test_keyword_settings_replace_the_spec_file_tables():
    base = gl.design(EXAMPLES / "pendulum.toml")
    heavier = gl.design(EXAMPLES / "pendulum.toml", R=[[10.0]])
    assert heavier.data["design"]["controller"]["R"] == [[10.0]]
    assert np.linalg.norm(heavier.K) < np.linalg.norm(base.K)  # costlier input: smaller gains


def test_own_gains_reproduce_the_designed_artifact_and_say_they_were_given():
    designed = gl.design(EXAMPLES / "pendulum.toml")
    given = gl.from_gains(
        EXAMPLES / "pendulum.toml",
        K=designed.K,
        Ki=designed.Ki,
        Ci=designed.Ci,
        L=designed.L,
        u_min=designed.u_min,
        u_max=designed.u_max,
    )
    for key in ("K", "Ki", "L", "Kaw", "Ad", "Bd"):
        np.testing.assert_array_equal(getattr(given, key), getattr(designed, key))
    assert given.checks["closed_loop_poles"] == designed.checks["closed_loop_poles"]
    assert given.checks["margins"] == designed.checks["margins"]
    assert given.provenance["gains"] == "given: controller, observer"
    assert given.data["design"]["controller"]["method"] == "given"


def test_current_form_gains_are_given_as_the_filter_gain():
    sysd = ct.c2d(_double_integrator(), 0.01)
    K, _, _ = ct.dlqr(sysd, np.diag([10.0, 1.0]), [[1.0]])
    L, _, _ = ct.dlqe(sysd.A, np.eye(2), sysd.C, np.diag([1e-4, 1e-3]), [[1e-5]])
    M = np.linalg.solve(sysd.A, L)
    art = gl.from_gains(sysd, K=K, M=M, u_min=[-5.0], u_max=[5.0])
    assert art.observer_form == "current"
    np.testing.assert_allclose(art.L, sysd.A @ M, rtol=1e-12)


def test_given_gains_get_every_design_check():
    sysd = ct.c2d(_double_integrator(), 0.01)
    L, _, _ = ct.dlqe(sysd.A, np.eye(2), sysd.C, np.diag([1e-4, 1e-3]), [[1e-5]])
    with pytest.raises(DesignError, match="closed loop is unstable"):
        gl.from_gains(sysd, K=[[-1.0, 0.0]], L=L, u_min=[-5.0], u_max=[5.0])  # positive feedback on position
    with pytest.raises(SpecError, match=r"controller.K is 1x3, expected 1x2"):
        gl.from_gains(sysd, K=[[1.0, 1.0, 1.0]], L=L, u_min=[-5.0], u_max=[5.0])
    with pytest.raises(SpecError, match="NaN or infinite"):
        gl.from_gains(sysd, K=[[np.nan, 1.0]], L=L, u_min=[-5.0], u_max=[5.0])
    with pytest.raises(SpecError, match="exactly one of L"):
        gl.from_gains(sysd, K=[[1.0, 1.0]], u_min=[-5.0], u_max=[5.0])
    with pytest.raises(SpecError, match="rows of the identity"):
        gl.from_gains(sysd, K=[[1.0, 1.0]], Ki=[[-1.0]], Ci=[[2.0]], L=L, u_min=[-5.0], u_max=[5.0])


def test_given_gains_from_a_spec_file_and_one_line_refusals(tmp_path):
    spec = (EXAMPLES / "pendulum.toml").read_text()
    designed = gl.design(EXAMPLES / "pendulum.toml")
    given = spec.replace(
        'method = "lqr"',
        f'method = "given"\nK = {json.dumps(designed.K.tolist())}\nKi = {json.dumps(designed.Ki.tolist())}',
    )
    given = given.replace("Q_diag = [10.0, 1.0, 100.0, 1.0]", "").replace("R_diag = [1.0]", "")
    given = given.replace('method = "kalman"', f'method = "given"\nL = {json.dumps(designed.L.tolist())}')
    given = "\n".join(line for line in given.splitlines() if not line.startswith(("W_diag", "V_diag")))
    (tmp_path / "given.toml").write_text(given)
    res = run_cli("design", str(tmp_path / "given.toml"), "--out", str(tmp_path / "out"))
    assert res.code == 0, res.err
    art = gl.load(tmp_path / "out" / "gains.json")
    np.testing.assert_array_equal(art.K, designed.K)
    (tmp_path / "bad.toml").write_text(
        given.replace('method = "given"\nK = ', 'method = "given"\nK = [[1.0]]\nX = ', 1)
    )
    assert_refused(
        ("design", tmp_path / "bad.toml", "--out", tmp_path / "bad"), "unknown key 'X' in controller", tmp_path
    )


def test_margins_are_actuator_margins_of_the_law_as_implemented():
    """Gain margins: scale the actuator by k in a closed loop written out here from the law (the observer
    is fed the controller's own command, never the actuator's) and find where it loses stability.
    Phase margin: python-control's margin of the loop -C_y(z) P(z) broken at the plant input."""
    a = gl.design(EXAMPLES / "pendulum.toml")
    mg = a.checks["margins"][0]

    def rho(k: float) -> float:
        n, q = a.n, a.q
        # x+ = Ad x + k Bd u;  xh+ = Ad xh + Bd u + L (Cd x - Cd xh);  z+ = z - Ts Ci Cd x;  u = -K xh - Ki z
        Acl = np.block(
            [
                [a.Ad, -k * a.Bd @ a.K, -k * a.Bd @ a.Ki],
                [a.L @ a.Cd, a.Ad - a.L @ a.Cd - a.Bd @ a.K, -a.Bd @ a.Ki],
                [-a.Ts * a.Ci @ a.Cd, np.zeros((q, n)), np.eye(q)],
            ]
        )
        return float(np.max(np.abs(np.linalg.eigvals(Acl))))

    up, down = 10 ** (mg["gain_margin_up_db"] / 20), 10 ** (mg["gain_margin_down_db"] / 20)
    assert rho(1.0) < 1
    assert rho(up * 0.99) < 1 < rho(up * 1.01)
    assert rho(down * 1.01) < 1 < rho(down * 0.99)
    P = ct.ss(a.Ad, a.Bd, a.Cd, a.Dd, a.Ts)
    Cy = ct.ss(
        np.block([[a.Ad - a.L @ a.Cd - a.Bd @ a.K, -a.Bd @ a.Ki], [np.zeros((a.q, a.n)), np.eye(a.q)]]),
        np.vstack([a.L, -a.Ts * a.Ci]),
        np.hstack([-a.K, -a.Ki]),
        np.zeros((a.m, a.p)),
        a.Ts,
    )
    w = np.logspace(-2, np.log10(np.pi / a.Ts), 20000)
    _, pm, _, wcp = ct.margin(ct.frd(-Cy * P, w))
    assert mg["phase_margin_deg"] == pytest.approx(pm, abs=0.2)
    assert mg["gain_crossover_rad_s"] == pytest.approx(wcp, rel=2e-3)


def test_controller_and_closed_loop_systems_match_the_law():
    a = gl.design(EXAMPLES / "pendulum.toml")
    ctrl, cl = a.controller(), a.closed_loop()
    assert ctrl.input_labels == ["x", "theta", "r_x"] and ctrl.output_labels == ["F"]
    assert cl.input_labels == ["r_x", "d_F"] and cl.output_labels == ["x", "theta", "F"]
    np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(cl.A)))[-1], a.checks["spectral_radius"], rtol=1e-9)
    # the controller system steps exactly like the float64 law while nothing saturates
    rng = np.random.default_rng(3)
    Y = rng.normal(scale=1e-3, size=(40, a.p))
    R = np.full((40, a.q), 1e-3)
    law = gl.replay(a, Y, R)
    resp = ct.forced_response(ctrl, T=np.arange(40) * a.Ts, U=np.hstack([Y, R]).T)
    assert not law.saturated.any()
    np.testing.assert_allclose(resp.outputs.reshape(-1), law.u[:, 0], rtol=1e-9, atol=1e-12)
    # integral action: unit DC gain from r_x to x
    step = ct.step_response(cl[["x"], ["r_x"]], T=20.0)
    assert step.outputs[-1] == pytest.approx(1.0, abs=1e-3)


def test_saved_artifact_is_readable_by_everyone_and_loads_back(tmp_path):
    a = gl.design(EXAMPLES / "quadrotor_lateral.toml")
    a.save(tmp_path / "gains.json")
    mode = stat.S_IMODE(os.stat(tmp_path / "gains.json").st_mode)
    assert mode & 0o044 == 0o044
    assert gl.Artifact.load(tmp_path / "gains.json").sha256 == a.sha256


def test_notebook_style_example_runs_untouched():
    """The Done-when script: ct.ss, own K from ct.dlqr, own L, gl.from_gains, margins in python-control,
    gl.replay(..., engine="native")."""
    g = runpy.run_path(str(ROOT / "examples" / "notebook_style.py"), run_name="__main__")
    art = g["art"]
    assert art.provenance["gains"].startswith("given")
    assert g["pm"] == pytest.approx(art.checks["margins"][0]["phase_margin_deg"], abs=0.2)
    assert g["step"].outputs[-1] == pytest.approx(1.0, abs=1e-3)
    span = float(art.u_max[0] - art.u_min[0])
    assert np.max(np.abs(g["native"].u[:50] - g["reference"].u[:50])) < 1e-4 * span


def test_hil_run_takes_an_artifact_object_and_returns_numpy_traces(tmp_path):
    """gl.hil.run with an in-memory artifact: the real CAN firmware node against the built-in pendulum."""
    from support.hil import udp_transport

    art = gl.design(EXAMPLES / "pendulum.toml")
    scenario = {
        "name": "api_run",
        "artifact": "unused.json",
        "duration": 2.0,
        "mode": "lockstep",
        "controller": "firmware",
        "step_timeout": 2.0,
        "plant": {"kind": "cart_pendulum"},
        "transport": udp_transport(),
        "initial_state": {"theta": 0.05},
        "reference": {"r_x": {"kind": "step", "at": 0.2, "value": 0.2}},
    }
    res = gl.hil.run(scenario, artifact=art, report=tmp_path / "report", plots=False)
    assert res.complete, res.reason
    assert res.trace.y.shape == (200, 2) and res.trace.got.all()
    assert res.info["artifact"]["sha256"] == art.sha256
    assert json.loads((tmp_path / "report" / "report.json").read_text())["complete"] is True
    assert abs(res.trace.y[-1, 1]) < 0.05  # the pendulum stays up


def test_own_gains_carry_an_operating_point():
    """From the law's text: with xh = 0, z = 0 and y = y_op the first command is u_op, and the
    estimate does not move (dy = 0, du = 0)."""
    sysd = ct.c2d(_double_integrator(), 0.01)
    K, _, _ = ct.dlqr(sysd, np.diag([10.0, 1.0]), [[1.0]])
    L, _, _ = ct.dlqe(sysd.A, np.eye(2), sysd.C, np.diag([1e-4, 1e-3]), [[1e-5]])
    art = gl.from_gains(sysd, K=K, L=L, u_min=[0.0], u_max=[20.0], u_op=[9.81], y_op=[2.0])
    np.testing.assert_array_equal(art.u_op, [9.81])
    np.testing.assert_array_equal(art.y_op, [2.0])
    tr = gl.replay(art, np.full((3, 1), 2.0))
    np.testing.assert_allclose(tr.u[:, 0], 9.81, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(tr.xh, 0.0)


def test_the_api_and_the_command_line_make_the_same_artifact_from_a_spec_file(tmp_path):
    """One path: ``gl.design(file)`` is ``gainlink design file`` byte for byte (the spec's hash is the file's own),
    and ``gainlink replay`` writes what ``gl.replay`` returns."""
    import hashlib

    spec = EXAMPLES / "pendulum.toml"
    assert run_cli("design", spec, "--out", tmp_path / "d").code == 0
    written = json.loads((tmp_path / "d" / "gains.json").read_text())
    art = gl.design(spec)
    assert art.sha256 == written["sha256"]
    assert art.provenance["spec_sha256"] == hashlib.sha256(spec.read_bytes()).hexdigest()
    sim = gl.simulate(art, steps=50, x0=[0.1, 0, 0.05, 0])
    rows = ["t,y0,y1,r0"] + [",".join(repr(float(v)) for v in (t, *y, *r)) for t, y, r in zip(sim.t, sim.y, sim.r)]
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    assert run_cli("replay", tmp_path / "d" / "gains.json", "--input", tmp_path / "in.csv",
                   "--output", tmp_path / "out.csv").code == 0  # fmt: skip
    out = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)
    np.testing.assert_array_equal(out["u0"], gl.replay(art, sim.y, sim.r).u[:, 0])
