"""The operating point (``u_op``, ``y_op``; ``x_op`` for the record): spec, artifact, float64 law, C loop, PIL.

Oracles, none of them the code under test:
- an independent transcription of the law in docs/design.md ("The control law") with the operating point,
  in lists and loops;
- the law's shift invariance, read off its text: a design about (u_op, y_op) fed ``y_op + s`` and references
  ``Ci y_op + rho`` has the same estimate and integrator as the same design about the origin fed ``s``, ``rho``,
  and commands ``u_op`` plus that design's command (its limits shifted by ``u_op`` too);
- the trim is an equilibrium: at ``y = y_op``, ``r = Ci y_op``, ``xh = z = 0`` every term but ``u_op`` is an
  exact zero, so even the float32 loop commands exactly ``float32(u_op)`` and its state stays exactly zero.
"""

from __future__ import annotations

import copy
import json
import logging
import math

import numpy as np
import pytest
from gainlink.engines import qemu as qemu_engine
from gainlink.engines.native import NativeLoop
from gainlink.errors import ArtifactError
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.laws import design as design_spec
from gainlink.laws.lq.golden import random_case
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping.artifact import from_dict, seal
from gainlink.spec import parse_spec
from support.cli import run_cli
from support.shared import once

GL_ERR_NANINF, GL_ERR_WATCHDOG = -2, -6
FORMS = ("predictor", "current")
MODES = ("none", "clamp", "backcalc")

# A DC motor's speed loop about its nominal point: 6 V gives 12 rad/s (the model is the deviation from it).
MOTOR = {
    "name": "motor",
    "Ts": 0.01,
    "plant": {
        "kind": "continuous",
        "A": [[-2.0, 1.0], [0.0, -10.0]],
        "B": [[0.0], [20.0]],
        "C": [[1.0, 0.0]],
        "states": ["speed", "current"],
        "inputs": ["volts"],
        "outputs": ["speed"],
    },
    "controller": {"method": "lqr", "Q_diag": [1.0, 0.01], "R_diag": [0.1]},
    "integral": {"outputs": ["speed"], "Q_diag": [10.0]},
    "observer": {"method": "kalman", "W_diag": [1e-3, 1e-3], "V_diag": [1e-4]},
    "limits": {"u_min": [0.0], "u_max": [12.0]},
}


pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def motor(**op) -> dict:
    spec = copy.deepcopy(MOTOR)
    if op:
        spec["operating_point"] = op
    return spec


def designed(spec: dict) -> dict:
    return design_spec(parse_spec(spec)).artifact


# --- spec and artifact ---------------------------------------------------------------------------------


def test_spec_takes_lists_or_names_and_the_artifact_records_them():
    by_list = parse_spec(motor(u_op=[6.0], y_op=[12.0], x_op=[12.0, 24.0])).operating_point
    by_name = parse_spec(motor(u_op={"volts": 6.0}, y_op={"speed": 12.0}, x_op={"current": 24.0, "speed": 12.0}))
    for op in (by_list, by_name.operating_point):
        assert op.u_op.tolist() == [6.0] and op.y_op.tolist() == [12.0] and op.x_op.tolist() == [12.0, 24.0]
    partial = parse_spec(motor(x_op={"current": 24.0})).operating_point
    assert partial.u_op.tolist() == [0.0] and partial.x_op.tolist() == [0.0, 24.0], "signals not named are zero"
    assert parse_spec(motor()).operating_point is None
    data = designed(motor(u_op=[6.0], y_op={"speed": 12.0}, x_op=[12.0, 24.0]))
    assert (data["u_op"], data["y_op"], data["x_op"]) == ([6.0], [12.0], [12.0, 24.0])
    art = from_dict(data)
    assert art.u_op.tolist() == [6.0] and art.y_op.tolist() == [12.0] and art.x_op.tolist() == [12.0, 24.0]
    assert art.r_op.tolist() == [12.0] and art.safe_command.tolist() == [6.0] and art.has_operating_point


def without(data: dict, *keys: str) -> dict:
    """``data`` without ``keys``, the hashes (its own and its spec's) and the hash over them."""
    out = {k: v for k, v in data.items() if k not in keys + ("sha256",)}
    out["provenance"] = {k: v for k, v in out["provenance"].items() if k != "spec_sha256"}
    return out


def test_operating_point_keys_are_written_only_when_non_zero():
    """Absent means zero, so a zero operating point writes what the spec without the table writes: the
    same content (only the spec's own hash differs, its text does), the same C, the same behaviour."""
    plain = designed(motor())
    zeros = designed(motor(u_op=[0.0], y_op={"speed": 0.0}, x_op=[0.0, 0.0]))
    assert not {"u_op", "y_op", "x_op"} & set(plain)
    assert without(zeros) == without(plain)
    only_u = designed(motor(u_op=[6.0]))
    assert only_u["u_op"] == [6.0] and "y_op" not in only_u and "x_op" not in only_u
    # the deviation design does not depend on the point: the same gains, every other key equal too, except the
    # float32 closed-loop check, which measures the C's rounding at that point (u_op enters its sums)
    f32 = only_u["checks"].pop("float32"), plain["checks"].pop("float32")
    assert without(only_u, "u_op") == without(plain)
    assert all(f["max_rel_u"] < 1e-4 for f in f32)


def test_artifact_without_operating_point_keeps_its_hash_and_means_zero(pend):
    """An artifact written before operating points existed (the pendulum example has none) loads, hashes as
    recorded, and means u_op = y_op = 0: the same file with explicit zero keys runs bit for bit the same."""
    data = json.loads(pend.read_text())
    assert not {"u_op", "y_op", "x_op"} & set(data)
    old = artifact_mod.load(pend)  # check_hash: the recorded sha256 still covers the content
    assert old.u_op.tolist() == [0.0] and old.y_op.tolist() == [0.0, 0.0] and old.x_op is None
    assert not old.has_operating_point and old.safe_command.tolist() == [0.0]
    explicit = from_dict(seal({**data, "u_op": [0.0], "y_op": [0.0, 0.0]}))
    assert explicit.sha256 != old.sha256
    rng = np.random.default_rng(3)
    Y, R = rng.normal(0.0, 0.5, (300, 2)), rng.normal(0.0, 0.5, (300, 1))
    Y[40, 1] = np.nan
    a, b = NativeLoop(old).run_raw(Y, R), NativeLoop(explicit).run_raw(Y, R)
    for key in a:
        assert np.array_equal(a[key].view(np.uint8), b[key].view(np.uint8)), key
    assert NativeLoop(old).default_gains().u_op[0] == 0.0
    want = independent_law(data, Y, R)
    assert np.allclose(a["u"][:, 0], [w[0][0] for w in want], atol=1e-4 * 20.0)


def test_loader_refuses_a_malformed_operating_point(pend):
    data = json.loads(pend.read_text())
    for key, value, words in (
        ("u_op", [1.0, 2.0], "u_op has length 2, expected 1"),
        ("y_op", [1.0], "y_op has length 1, expected 2"),
        ("x_op", [0.0], "x_op has length 1, expected 4"),
        ("y_op", [1.0, "a"], "is not of type 'number'"),
    ):
        with pytest.raises(ArtifactError, match=words):
            from_dict(seal({**data, key: value}))


# --- the float64 law -----------------------------------------------------------------------------------


def matvec(A, x):
    return [sum(a * b for a, b in zip(row, x)) for row in A]


def independent_law(data: dict, Y, R):
    """The step of docs/design.md with the operating point, in lists and loops, from the artifact's JSON dict.

    Returns per step (u, saturated, fault, xh, z)."""
    n, m, p, q = data["n"], data["m"], data["p"], data["q"]
    Ad, Bd, Cd, Dd, K, L = (data[k] for k in ("Ad", "Bd", "Cd", "Dd", "K", "L"))
    Ci, Ki, Kaw, M = data.get("Ci", []), data.get("Ki", [[] for _ in range(m)]), data.get("Kaw", []), data.get("M")
    u_op, y_op = data.get("u_op", [0.0] * m), data.get("y_op", [0.0] * p)
    Ts, aw, form, lo, hi = data["Ts"], data["anti_windup"], data["observer_form"], data["u_min"], data["u_max"]
    xh, z, out = [0.0] * n, [0.0] * q, []
    for y, r in zip(np.asarray(Y, float).tolist(), np.asarray(R, float).tolist()):
        if not all(math.isfinite(v) for v in y + r):
            out.append(([min(max(u_op[i], lo[i]), hi[i]) for i in range(m)], [False] * m, True, list(xh), list(z)))
            continue
        dy = [y[k] - y_op[k] for k in range(p)]
        if form == "current":
            innov = [dy[k] - matvec(Cd, xh)[k] for k in range(p)]
            xc = [xh[i] + matvec(M, innov)[i] for i in range(n)]
        else:
            xc = xh
        v = [u_op[i] - matvec(K, xc)[i] - (matvec(Ki, z)[i] if q else 0.0) for i in range(m)]
        u = [min(max(v[i], lo[i]), hi[i]) for i in range(m)]
        sat = [u[i] != v[i] for i in range(m)]
        e = [r[j] - matvec(Ci, y)[j] for j in range(q)]
        if aw == "none" or (aw == "clamp" and not any(sat)):
            z = [z[j] + Ts * e[j] for j in range(q)]
        elif aw == "backcalc":
            corr = matvec(Kaw, [u[i] - v[i] for i in range(m)])
            z = [z[j] + Ts * e[j] + corr[j] for j in range(q)]
        du = [u[i] - u_op[i] for i in range(m)]
        if form == "current":
            xh = [matvec(Ad, xc)[i] + matvec(Bd, du)[i] for i in range(n)]
        else:
            innov = [dy[k] - matvec(Cd, xh)[k] - matvec(Dd, du)[k] for k in range(p)]
            xh = [matvec(Ad, xh)[i] + matvec(Bd, du)[i] + matvec(L, innov)[i] for i in range(n)]
        out.append((u, sat, False, list(xh), list(z)))
    return out


def op_case(form: str, mode: str, *, N: int = 300):
    """A random saturating design about a non-zero operating point, with absolute samples (golden generator)."""
    dims = {"predictor": dict(n=4, m=2, p=3), "current": dict(n=5, m=2, p=2)}[form]
    return once(
        f"op_case-{form}-{mode}-{N}",
        lambda: random_case(
            300 + FORMS.index(form) * 3 + MODES.index(mode),
            q=0 if mode == "none" else 1,
            form=form,
            anti_windup=mode,
            N=N,
            operating_point=True,
            **dims,
        ),
    )


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("mode", MODES)
def test_reference_equals_independent_law_with_operating_point(form, mode):
    case = op_case(form, mode)
    a = case.artifact
    assert np.all(np.abs(a.u_op) > 0.1) and np.all(np.abs(a.y_op) > 0.1)
    Y, R = case.Y.copy(), case.R.copy()
    Y[60, 0] = np.nan
    trace = ReferenceLoop(a).run(Y, R)
    for k, (u, sat, fault, xh, z) in enumerate(independent_law(a.data, Y, R)):
        np.testing.assert_allclose(trace.u[k], u, rtol=1e-12, atol=1e-12, err_msg=f"step {k}")
        assert list(trace.saturated[k]) == sat and trace.fault[k] == fault, f"step {k}"
        np.testing.assert_allclose(trace.xh[k], xh, rtol=1e-11, atol=1e-11, err_msg=f"step {k}")
        np.testing.assert_allclose(trace.z[k], z, rtol=1e-11, atol=1e-11, err_msg=f"step {k}")
    assert trace.saturated.any() and not trace.saturated.all() and trace.fault[60]


@pytest.mark.parametrize("form", FORMS)
def test_law_is_shift_invariant(form):
    """About (u_op, y_op) with y_op + s, Ci y_op + rho in: u_op + the origin design's command out, same state."""
    shifted = op_case(form, "backcalc")
    seed = 300 + FORMS.index(form) * 3 + 2
    dims = {"predictor": dict(n=4, m=2, p=3), "current": dict(n=5, m=2, p=2)}[form]
    origin = random_case(seed, q=1, form=form, anti_windup="backcalc", N=300, **dims)
    a, b = shifted.artifact, origin.artifact
    assert np.array_equal(a.K, b.K) and np.allclose(a.u_min - a.u_op, b.u_min, rtol=0, atol=1e-14)
    np.testing.assert_allclose(shifted.Y - a.y_op, origin.Y, atol=1e-12)
    ta, tb = ReferenceLoop(a).run(shifted.Y, shifted.R), ReferenceLoop(b).run(origin.Y, origin.R)
    np.testing.assert_allclose(ta.u - a.u_op, tb.u, atol=1e-9)
    np.testing.assert_allclose(ta.xh, tb.xh, atol=1e-9)
    np.testing.assert_allclose(ta.z, tb.z, atol=1e-9)
    assert np.array_equal(ta.saturated, tb.saturated) and tb.saturated.any()


# --- the C loop ----------------------------------------------------------------------------------------


def rel_err(got: np.ndarray, want: np.ndarray) -> float:
    return float(np.max(np.abs(got - want))) / max(float(np.max(np.abs(want))), 1e-9)


# float32 C vs float64 law: see tests/test_firmware_host.py for the bound (1e-4 of the signal's size).
RTOL = 1e-4


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("mode", MODES)
def test_c_loop_equals_the_law_with_operating_point(form, mode):
    """Host C (float32) against the independent law fed the same float32 samples; and the same C against
    the law with the operating point dropped disagrees by far more than the tolerance (the test can fail)."""
    case = op_case(form, mode)
    a = case.artifact
    Y, R = case.Y.copy(), case.R.copy()
    Y[33, 1] = np.inf
    raw = NativeLoop(a).run_raw(Y, R)
    Y32, R32 = Y.astype(np.float32).astype(float), R.astype(np.float32).astype(float)
    want = independent_law(a.data, Y32, R32)
    u = np.array([w[0] for w in want])
    xh = np.array([w[3] for w in want])
    z = np.array([w[4] for w in want]).reshape(len(want), a.q)
    assert rel_err(raw["u"].astype(float), u) <= RTOL
    assert rel_err(raw["xh"].astype(float), xh) <= RTOL
    if a.q:
        assert rel_err(raw["z"].astype(float), z) <= RTOL
    assert np.array_equal(raw["fault"].astype(bool), [w[2] for w in want])
    assert np.any([any(w[1]) for w in want]), "the samples saturate"
    blind = independent_law({k: v for k, v in a.data.items() if k not in ("u_op", "y_op")}, Y32, R32)
    assert rel_err(raw["u"].astype(float), np.array([w[0] for w in blind])) > 100 * RTOL


def test_trim_is_an_exact_equilibrium_of_the_c_loop():
    """At y = y_op, r = Ci y_op from a zero state, the float32 loop commands exactly float32(u_op) forever."""
    for form in FORMS:
        a = op_case(form, "backcalc").artifact
        N = 500
        Y, R = np.tile(a.y_op, (N, 1)), np.tile(a.r_op, (N, 1))
        raw = NativeLoop(a).run_raw(Y, R)
        assert np.array_equal(raw["u"], np.tile(a.u_op.astype(np.float32), (N, 1)))
        assert not raw["xh"].any() and not raw["z"].any() and not raw["sat"].any()
        # the same design blind to its operating point pushes the plant off its trim on every step
        blind = from_dict(seal({k: v for k, v in a.data.items() if k not in ("u_op", "y_op")}))
        assert np.all(np.max(np.abs(ReferenceLoop(blind).run(Y, R).u - a.u_op), axis=1) > 0.01)


def safe_case():
    """A design whose u_op is moved outside its limits for one input (the artifact is edited and resealed:
    design refuses such a spec, the loader and the C accept it and clamp)."""
    a = op_case("predictor", "clamp").artifact
    data = copy.deepcopy(a.data)
    data["u_op"] = [data["u_max"][0] + 3.0, data["u_op"][1]]
    return from_dict(seal(data))


def test_safe_command_is_u_op_clamped():
    a = safe_case()
    expected = np.array([a.u_max[0], a.u_op[1]])
    assert np.array_equal(a.safe_command, expected) and expected[1] != 0.0
    loop = NativeLoop(a, watchdog_periods=3)
    assert loop.step([np.nan] * a.p, a.r_op).status == GL_ERR_NANINF
    assert np.array_equal(loop.step([0.0] * a.p, [np.inf]).u, expected.astype(np.float32))
    for _ in range(2):
        loop.idle()
    expired = loop.idle()
    assert expired.status == GL_ERR_WATCHDOG and np.array_equal(expired.u, expected.astype(np.float32))
    res = ReferenceLoop(a).step([np.nan] * a.p, a.r_op)
    assert res.fault and np.array_equal(res.u, expected)


def test_host_and_qemu_bit_for_bit_with_a_saturated_safe_command():
    """The Cortex-M4F image equals the host library bit for bit about an operating point whose u_op lies outside
    the limits: the refused sample's safe command is u_op clamped. (The random designs about operating points,
    every form and anti-windup mode, run in tests/test_firmware_qemu.py.)"""
    a = safe_case()
    Y, R = _op_samples(a)
    Y[11, 0] = np.nan
    host, target = NativeLoop(a).run_raw(Y, R), qemu_engine.run_raw(a, Y, R)
    for key in ("u", "sat", "xh", "z", "fault"):
        assert np.array_equal(host[key].view(np.uint8), target[key].view(np.uint8)), f"{a.name}: {key}"
    assert np.array_equal(target["u"][11], a.safe_command.astype(np.float32))
    assert np.any(a.safe_command != a.u_op), "the safe command is the clamped u_op"


def _op_samples(a, N: int = 200):
    rng = np.random.default_rng(5)
    return a.y_op + rng.normal(0, 1.0, (N, a.p)), a.r_op + rng.normal(0, 1.0, (N, a.q))


# --- simulate, replay and PIL: absolute samples ------------------------------------------------------


def test_simulate_records_absolute_samples_and_replays(tmp_path):
    """`gainlink simulate` on a design about 6 V / 12 rad/s records absolute speeds and volts; with no
    reference given it holds the trim; replay through the C reproduces the recorded commands."""
    art = tmp_path / "gains.json"
    artifact_mod.write(art, designed(motor(u_op=[6.0], y_op=[12.0])))
    held, step = tmp_path / "held.csv", tmp_path / "step.csv"
    assert run_cli("simulate", art, "--steps", "50", "--out", held).code == 0
    rows = np.genfromtxt(held, delimiter=",", names=True)
    assert np.all(rows["y0"] == 12.0) and np.all(rows["r0"] == 12.0)
    assert run_cli("simulate", art, "--steps", "800", "--ref", "14.0", "--out", step).code == 0
    rows = np.genfromtxt(step, delimiter=",", names=True)
    assert rows["y0"][0] == 12.0 and abs(rows["y0"][-1] - 14.0) < 1e-3, "settles on the absolute reference"
    res = run_cli("replay", art, "--input", step, "--output", tmp_path / "ref.csv")
    assert res.code == 0
    out = np.genfromtxt(tmp_path / "ref.csv", delimiter=",", names=True)
    a = artifact_mod.load(art)
    # at 14 rad/s the motor needs 7 V: the deviation model says du = 2 V for dy = 2 rad/s (gain 1 V per 1 rad/s)
    dc_gain = float((a.Cd @ np.linalg.solve(np.eye(a.n) - a.Ad, a.Bd))[0, 0])
    assert out["u0"][-1] == pytest.approx(6.0 + 2.0 / dc_gain, abs=1e-3)
    res = run_cli(
        "replay",
        art,
        "--input",
        step,
        "--output",
        tmp_path / "c.csv",
        "--engine",
        "native",
        "--compare",
        tmp_path / "ref.csv",
    )
    assert res.code == 0, res.err


def test_pil_closes_the_loop_about_the_operating_point():
    """PIL: the M4F image in QEMU against the artifact's plant about its point (absolute samples) tracks an
    absolute reference and equals the float64 law in the same loop."""
    a = from_dict(designed(motor(u_op=[6.0], y_op=[12.0])))
    steps, reference = 600, [14.0]
    res = run_pil(
        a,
        plant=make_plant("artifact", artifact=a, x0=np.zeros(a.n)),
        steps=steps,
        reference=reference,
        twin=make_plant("artifact", artifact=a, x0=np.zeros(a.n)),
    )
    Y, U = res.twin.y, res.twin.u  # the float64 law in the same loop
    assert res.y[0, 0] == 12.0 and res.u[0, 0] == np.float32(6.0), "starts at the trim, bumplessly"
    assert rel_err(res.u.astype(float), U) <= RTOL and rel_err(res.y, Y) <= RTOL
    assert abs(res.y[-1, 0] - 14.0) < 1e-3


# --- the HIL side: the linear plant about its point, references and the first command ---------------


def test_linear_plant_is_about_the_operating_point(tmp_path):
    """``kind = "linear"`` from an artifact with an operating point: at rest at the trim it stays there under
    u_op; a held step of the command gives y_op plus python-control's step response of (A, B, C, D)."""
    import control
    from gainlink.hil.plants import toml_write
    from gainlink.hil.plants.linear import LinearPlant, model_from_artifact, model_from_spec

    a = from_dict(designed(motor(u_op=[6.0], y_op=[12.0])))
    plant = LinearPlant(model=model_from_artifact(a))
    plant.reset(initial={})
    for _ in range(50):
        assert plant.outputs().tolist() == [12.0]
        plant.advance(u=np.array([6.0]), dt=0.01)
    N, dt = 300, 0.01
    Y = np.zeros(N)
    for k in range(N):
        plant.advance(u=np.array([6.5]), dt=dt)
        Y[k] = plant.outputs()[0]
    sys = control.ss(MOTOR["plant"]["A"], MOTOR["plant"]["B"], MOTOR["plant"]["C"], [[0.0]])
    resp = control.forced_response(sys, T=np.arange(N + 1) * dt, U=np.full(N + 1, 0.5))
    np.testing.assert_allclose(Y, 12.0 + resp.outputs[1:], rtol=1e-9, atol=1e-12)
    spec = tmp_path / "motor.toml"
    spec.write_text(toml_write.dumps(motor(u_op=[6.0], y_op=[12.0])))
    from_spec = model_from_spec(spec)
    assert from_spec.u_op.tolist() == [6.0] and from_spec.y_op.tolist() == [12.0]


def test_hil_bridge_starts_at_the_trim_and_references_are_absolute(tmp_path):
    """A HIL run (Python reference controller over udp_multicast CAN, linear plant about the point): the
    bridge's first command is u_op (clamped), a reference without a profile holds the trim, a step profile
    without `initial` starts from it; the loop sits exactly at 12 rad/s and 6 V until the step to 14."""
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import parse_scenario
    from support.hil import udp_transport

    art = tmp_path / "gains.json"
    artifact_mod.write(art, designed(motor(u_op=[6.0], y_op=[12.0])))
    base = {
        "artifact": str(art),
        "duration": 6.0,
        "controller": "reference",
        "step_timeout": 2.0,
        "plant": {"kind": "linear"},
        "transport": udp_transport(),
    }
    held = run_scenario(parse_scenario(base))
    assert held.complete and held.metrics["lost"] == 0
    assert np.all(held.trace.y == 12.0) and np.all(held.trace.u == 6.0) and np.all(held.trace.r == 12.0)
    step = run_scenario(parse_scenario({**base, "reference": {"r_speed": {"kind": "step", "at": 1.0, "value": 14.0}}}))
    t, y, r = step.trace.t, step.trace.y[:, 0], step.trace.r[:, 0]
    assert np.all(r[t < 1.0] == 12.0) and np.all(r[t >= 1.0] == 14.0)
    assert np.all(y[t < 1.0] == 12.0) and abs(y[-1] - 14.0) < 1e-2


def test_linearize_at_a_point_that_is_not_a_trim_says_so(tmp_path, caplog):
    """The cart pendulum tilted 0.1 rad with no force is not at rest: the spec records that point (x_op, y_op)
    and says it is not an equilibrium, in the log and in the spec's header, naming the derivatives."""
    import tomllib

    from gainlink.hil.plants.build import build_fmu

    out = tmp_path / "tilted.toml"
    with caplog.at_level(logging.WARNING):
        res = run_cli("linearize", build_fmu("cart_pendulum"), "--at", "theta=0.1", "--out", out)
    assert res.code == 0, res.err
    assert "not an equilibrium" in caplog.text and "dtheta_dot/dt" in caplog.text
    text = out.read_text()
    assert "# Not an equilibrium: " in text
    op = tomllib.loads(text)["operating_point"]
    assert op["x_op"]["theta"] == 0.1 and op["y_op"] == {"x": 0.0, "theta": 0.1} and op["u_op"] == {"F": 0.0}


def test_float32_accuracy_does_not_scale_with_a_large_operating_point():
    """A barometric altimeter reads 350 m above sea level at the hover point; the deviations are centimetres.
    The C subtracts y_op before any gain (and forms the feedback in deviations), so its estimate stays within
    the float32 rounding of the deviations. Folding the offsets into constants (xh+ = F xh + G u + L y + c,
    c = -(G u_op + L y_op)) would round each step at the scale of 350 m: emulated in numpy float32 here, that
    is ~1e-2 of the speed estimate, against ~1e-6 for the C (measured)."""
    spec = {
        "name": "baro",
        "Ts": 0.01,
        "plant": {"kind": "continuous", "A": [[0.0, 1.0], [0.0, 0.0]], "B": [[0.0], [28.0]], "C": [[1.0, 0.0]]},
        "controller": {"method": "lqr", "Q_diag": [4.0, 1.0], "R_diag": [1.0]},
        "observer": {"method": "kalman", "W_diag": [1e-6, 1e-4], "V_diag": [1e-6]},
        "limits": {"u_min": [0.0], "u_max": [1.0]},
        "operating_point": {"u_op": [0.7], "y_op": [350.0]},
    }
    a = from_dict(designed(spec))
    rng = np.random.default_rng(0)
    N = 3000
    Y = 350.0 + 0.05 * np.sin(np.arange(N) * 0.01) + 0.001 * rng.standard_normal(N)
    Y32 = Y.astype(np.float32).astype(float).reshape(N, 1)
    want = ReferenceLoop(a).run(Y32, np.zeros((N, 0)))
    got = NativeLoop(a).run_raw(Y32, np.zeros((N, 0)))
    err = np.max(np.abs(got["xh"] - want.xh), axis=0) / np.max(np.abs(want.xh), axis=0)
    assert np.all(err < 1e-4), err
    # the folded form, emulated in float32, for scale
    f32 = np.float32
    F, G, L = (a.Ad - a.L @ a.Cd).astype(f32), a.Bd[:, 0].astype(f32), a.L[:, 0].astype(f32)
    c = (-(a.Bd[:, 0] * 0.7 + a.L[:, 0] * 350.0)).astype(f32)
    xh, folded = np.zeros(2, f32), np.zeros((N, 2))
    for k in range(N):
        u = min(max(f32(f32(0.7) - (a.K.astype(f32) @ xh)[0]), f32(0.0)), f32(1.0))
        xh = (F @ xh + G * f32(u) + L * f32(Y32[k, 0]) + c).astype(f32)
        folded[k] = xh
    folded_err = np.max(np.abs(folded - want.xh), axis=0) / np.max(np.abs(want.xh), axis=0)
    assert folded_err[1] > 100 * err[1], (folded_err, err)
