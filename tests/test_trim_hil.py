"""The trim test: a nonlinear plant that hovers at a non-zero trim, linearised there, designed, run in HIL.

The plant is the project's own FMU ``multirotor_vertical``: throttle in (thrust ``k_T u^2``), altitude out,
quadratic drag and a ground. It hovers where thrust equals weight, at throttle ``u_hover = sqrt(m g / k_T)``
(0.70 with its defaults), at any altitude. ``gainlink linearize --at z=2 --at throttle=u_hover`` writes the
spec with ``[operating_point]`` (throttle 0.70, altitude 2 m); the design is an altitude-hold regulator about
that point, so its set point is the trim altitude ``y_op = 2 m``.

Why a regulator and not integral action: an integrator on the altitude learns the hover throttle by itself,
so a design with one settles on its reference whether the artifact carries the operating point or not; the
operating point then only buys the start (no drop while the integrator winds up). The last test here shows
exactly that, with numbers. The regulator is where the operating point decides the steady state: blind to
``y_op`` it regulates the absolute altitude towards zero, blind to ``u_op`` it needs an altitude error to
make any thrust at all. Solving the law of docs/design.md ("The control law") at rest (observer fixed point
plus thrust = weight) gives its equilibrium below the ground, so the blind design lands; with the operating
point the same equations give exactly 2 m.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from gainlink.firmware.mavlink_app import MavlinkFirmware, mavlink_executable
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.hil.plants.build import build_fmu
from gainlink.shipping.artifact import from_dict, load, render, seal
from gainlink.shipping.codegen import c_float
from support.cli import run_cli
from support.hil import udp_transport
from support.net import udp_port

Z_SET = 2.0  # m: the altitude the plant is linearised at, the regulator's set point

TEMPLATE = """\
name = "template"
Ts = 0.01
[plant]
A = [[0.0]]
B = [[1.0]]
C = [[1.0]]
[controller]
method = "lqr"
Q_diag = [4.0, 1.0]
R_diag = [1.0]
[observer]
method = "kalman"
W_diag = [1e-6, 1e-4]
V_diag = [1e-6]
[limits]
u_min = [0.0]
u_max = [1.0]
"""


pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def fmu_parameters(fmu: Path) -> dict:
    """Start values of the FMU's parameters, read from its model description."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return {v.name: float(v.start) for v in md.modelVariables if v.causality == "parameter"}


# the five tests read one linearization and design (3 CPU-s): one worker makes it for them, not each that meets one
pytestmark = pytest.mark.xdist_group("test_trim_hil")


@pytest.fixture(scope="module")
def hover(tmp_path_factory) -> dict:
    """FMU -> ``gainlink linearize --at`` -> spec -> ``gainlink design`` -> artifact; and the same artifact
    with its operating point removed (resealed: the "blind" design)."""
    tmp = tmp_path_factory.mktemp("hover")
    fmu = build_fmu("multirotor_vertical")
    par = fmu_parameters(fmu)
    u_hover = math.sqrt(par["mass"] * par["g"] / par["k_T"])
    (tmp / "template.toml").write_text(TEMPLATE)
    spec = tmp / "hover.toml"
    res = run_cli(
        "linearize",
        fmu,
        "--at",
        f"z={Z_SET!r}",
        "--at",
        f"throttle={u_hover!r}",
        "--name",
        "hover",
        "--template",
        tmp / "template.toml",
        "--out",
        spec,
    )
    assert res.code == 0, res.err
    assert run_cli("design", spec, "--out", tmp / "design").code == 0
    art = tmp / "design" / "gains.json"
    data = json.loads(art.read_text())
    blind = tmp / "blind.json"
    blind.write_text(render(seal({k: v for k, v in data.items() if k not in ("u_op", "y_op", "x_op")})))
    return {"fmu": fmu, "par": par, "u_hover": u_hover, "spec": spec, "artifact": art, "blind": blind}


def test_linearize_writes_the_operating_point_and_the_hover_model(hover):
    spec = tomllib.loads(hover["spec"].read_text())
    op = spec["operating_point"]
    assert op["u_op"] == {"throttle": hover["u_hover"]} and op["y_op"] == {"z": Z_SET}
    assert op["x_op"] == {"z": Z_SET, "w": 0.0}
    par = hover["par"]
    # hover: w = 0, thrust k_T u^2 = m g; d(w_dot)/du = 2 k_T u / m, drag has no slope at w = 0
    np.testing.assert_allclose(spec["plant"]["A"], [[0.0, 1.0], [0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(
        spec["plant"]["B"], [[0.0], [2.0 * par["k_T"] * hover["u_hover"] / par["mass"]]], rtol=1e-12
    )
    a = load(hover["artifact"])
    assert a.u_op.tolist() == [hover["u_hover"]] and a.y_op.tolist() == [Z_SET] and a.q == 0
    assert a.x_op.tolist() == [Z_SET, 0.0]


def law_equilibrium(data: dict, *, u_rest: float) -> float:
    """The measured altitude at which docs/design.md's law (q = 0, predictor form) rests commanding ``u_rest``.

    At rest ``xh = Ad xh + Bd du + L (dy - Cd xh)`` with ``dy = z - y_op``, ``du = u_rest - u_op``, and
    ``u_rest = u_op - K xh``: n + 1 linear equations in ``xh`` and ``z``, solved with numpy.
    """
    Ad, Bd, Cd, K, L = (np.array(data[k], float) for k in ("Ad", "Bd", "Cd", "K", "L"))
    u_op = data.get("u_op", [0.0])[0]
    y_op = data.get("y_op", [0.0])[0]
    n = Ad.shape[0]
    du = u_rest - u_op
    A = np.zeros((n + 1, n + 1))
    b = np.zeros(n + 1)
    A[:n, :n] = np.eye(n) - Ad + L @ Cd
    A[:n, n] = -L[:, 0]  # the measured z
    b[:n] = Bd[:, 0] * du - L[:, 0] * y_op
    A[n, :n] = K[0]
    b[n] = u_op - u_rest
    return float(np.linalg.solve(A, b)[n])


def hil_run(artifact: Path, fmu: Path, *, duration: float = 8.0):
    """Lockstep HIL: the firmware's CAN node (real host process) over udp_multicast CAN FD, the FMU plant,
    starting 1 m below the set point."""
    return run_scenario(
        parse_scenario(
            {
                "name": "hover_trim",
                "artifact": str(artifact),
                "duration": duration,
                "mode": "lockstep",
                "controller": "firmware",
                "step_timeout": 2.0,
                "peer_timeout": 4.0,
                "twin": True,
                # The ground contact is the FMU's Co-Simulation interface's (its Model Exchange integrates the
                # free-flight derivatives): with interface = "auto" the blind design, whose operating point is zero
                # throttle, would run through Model Exchange (Co-Simulation does not reproduce it there: the fall
                # stops at the ground) and fall through the ground.
                "plant": {"kind": "fmu", "path": str(fmu), "outputs": ["z"], "interface": "cs"},
                "transport": udp_transport(fd=True),
                "initial_state": {"z": Z_SET - 1.0},
            }
        )
    )


@pytest.mark.slow
def test_hil_holds_the_trim_altitude_only_with_the_operating_point(hover):
    """With u_op, y_op: from 1 m the vehicle climbs to 2 m and holds it (error < 1 mm over the last second),
    the throttle settles at u_hover. The same gains blind to the operating point land the vehicle: the law's
    own rest point is below the ground (computed here from the law), so it ends on the ground, 2 m off."""
    data = json.loads(hover["artifact"].read_text())
    blind_data = json.loads(hover["blind"].read_text())
    assert law_equilibrium(data, u_rest=hover["u_hover"]) == pytest.approx(Z_SET, abs=1e-9)
    z_blind = law_equilibrium(blind_data, u_rest=hover["u_hover"])
    assert z_blind < -0.5, z_blind

    good = hil_run(hover["artifact"], hover["fmu"])
    assert good.complete and good.metrics["lost"] == 0
    t, z, u = good.trace.t, good.trace.y[:, 0], good.trace.u[:, 0]
    last = t >= t[-1] - 1.0
    assert np.max(np.abs(z[last] - Z_SET)) < 1e-3, np.max(np.abs(z[last] - Z_SET))
    assert u[-1] == pytest.approx(hover["u_hover"], abs=1e-4)
    assert z[0] == pytest.approx(Z_SET - 1.0) and good.metrics["twin"]["inputs"]["throttle"]["max_du_rel"] < 1e-4

    bad = hil_run(hover["blind"], hover["fmu"])
    assert bad.complete and bad.metrics["lost"] == 0
    zb, ub = bad.trace.y[:, 0], bad.trace.u[:, 0]
    assert np.all(zb[last] == 0.0), "the blind design put the vehicle on the ground"
    assert abs(zb[-1] - Z_SET) == Z_SET
    assert np.all(ub[last] < hover["u_hover"]), "and asks for less thrust than the weight: it stays there"


def test_firmware_build_and_mavlink_upload_carry_the_operating_point(hover, tmp_path):
    """`gainlink firmware build` bakes u_op/y_op into the generated gain set; `gainlink mavlink upload` to a
    vehicle running the blind design sets GL_UOP_0/GL_YOP_0 (read back with pymavlink: the artifact's float32
    values) and the loop then runs on them: at y = y_op from a reset it commands exactly u_op, and a refused
    sample gets u_op clamped."""
    from pymavlink import mavutil

    art, blind = load(hover["artifact"]), load(hover["blind"])
    out = tmp_path / "fw"
    assert run_cli("firmware", "build", hover["artifact"], "--target", "host", "--out", out).code == 0
    src = (out / "src" / "gl_gains.c").read_text()
    assert f".u_op = {{{c_float(art.u_op[0])}}}," in src and f".y_op = {{{c_float(Z_SET)}}}," in src

    port = udp_port()
    fw = MavlinkFirmware(mavlink_executable(blind), url=f"udpin:127.0.0.1:{port}")
    fw.start()
    try:
        before = trim_response(port, art)
        assert before[0] != np.float32(art.u_op[0]), "the blind design does not hold the trim"
        res = run_cli("mavlink", "upload", hover["artifact"], "--connect", f"udpout:127.0.0.1:{port}")
        assert res.code == 0, res.err
        conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=250)
        try:
            conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.wait_heartbeat(timeout=5)
            got = {name: read_param(conn, name) for name in ("GL_UOP_0", "GL_YOP_0")}
        finally:
            conn.close()
        assert got["GL_UOP_0"] == np.float32(art.u_op[0]) and got["GL_YOP_0"] == np.float32(Z_SET), got
        trim_u, safe_u = trim_response(port, art)
        assert trim_u == np.float32(art.u_op[0]) and safe_u == np.float32(art.safe_command[0])
    finally:
        fw.stop()


def read_param(conn, name: str) -> float:
    conn.mav.param_request_read_send(1, 1, name.encode(), -1)
    msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=5)
    while msg is not None and msg.param_id != name:
        msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=5)
    assert msg is not None, f"no PARAM_VALUE for {name}"
    return float(np.float32(msg.param_value))


def trim_response(port: int, art) -> tuple[np.float32, np.float32]:
    """Over the HIL link: reset, one sample at y = y_op (the command), then a NaN sample (the safe command)."""
    t = MavlinkTransport(
        url=f"udpout:127.0.0.1:{port}", controller_url="", n_inputs=art.m, n_outputs=art.p, n_refs=art.q, ts=art.Ts
    )
    with t:
        t.send_frames(t.encode_reset(seq=0))
        assert t.receive_command(timeout=2.0) is not None
        t.send_frames(t.encode_sample(seq=1, y=np.array([Z_SET]), r=np.zeros(0)))
        trim = t.receive_command(timeout=2.0)
        t.send_frames(t.encode_sample(seq=2, y=np.array([np.nan]), r=np.zeros(0)))
        safe = t.receive_command(timeout=2.0)
    assert trim is not None and safe is not None
    return np.float32(trim.u[0]), np.float32(safe.u[0])


def fmu_closed_loop(
    data: dict, fmu: Path, *, steps: int, step_at: float, step_to: float
) -> tuple[np.ndarray, np.ndarray]:
    """The FMU (fmpy, Co-Simulation) under the float64 law, from rest at the trim; reference steps at ``step_at``."""
    from gainlink.hil.plants.fmu import FmuPlant
    from gainlink.proof.reference import ReferenceLoop

    a = from_dict(data)
    law = ReferenceLoop(a)
    plant = FmuPlant(path=fmu, outputs=["z"])
    try:
        plant.reset(initial={"z": Z_SET})
        Z, U = np.zeros(steps), np.zeros(steps)
        for k in range(steps):
            Z[k] = plant.outputs()[0]
            U[k] = law.step([Z[k]], [step_to if k * a.Ts >= step_at else Z_SET]).u[0]
            plant.advance(u=U[k : k + 1], dt=a.Ts)
    finally:
        plant.close()
    return Z, U


def test_with_integral_action_both_settle_and_the_operating_point_buys_the_start(hover):
    """Why the HIL test uses a regulator: add integral action on the altitude (LQI) and both artifacts settle
    on a 2 m -> 2.5 m reference step with zero steady-state error, because the integrator learns the hover
    throttle itself. The operating point then decides the start: with it the vehicle, at rest at the trim,
    gets exactly u_hover and does not move; blind, it gets zero throttle and drops (0.19 m here) before the
    integrator has wound up the hover throttle."""
    from gainlink.laws import design as design_spec
    from gainlink.spec import parse_spec

    spec = tomllib.loads(hover["spec"].read_text())
    spec["integral"] = {"outputs": ["z"], "Q_diag": [4.0]}
    spec["limits"]["anti_windup"] = "backcalc"
    data = design_spec(parse_spec(spec)).artifact
    blind = seal({k: v for k, v in data.items() if k not in ("u_op", "y_op", "x_op")})
    steps, step_at = 1500, 5.0
    Z, U = fmu_closed_loop(data, hover["fmu"], steps=steps, step_at=step_at, step_to=Z_SET + 0.5)
    Zb, Ub = fmu_closed_loop(blind, hover["fmu"], steps=steps, step_at=step_at, step_to=Z_SET + 0.5)
    last = slice(steps - 100, steps)
    assert np.max(np.abs(Z[last] - (Z_SET + 0.5))) < 1e-3 and np.max(np.abs(Zb[last] - (Z_SET + 0.5))) < 1e-3
    before = slice(0, int(step_at / 0.01))
    assert U[0] == hover["u_hover"] and np.max(np.abs(Z[before] - Z_SET)) < 1e-9, "bumpless at the trim"
    assert Ub[0] == 0.0 and Z_SET - np.min(Zb[before]) > 0.1, Z_SET - np.min(Zb[before])  # 0.19 m measured


@pytest.mark.slow
def test_hil_with_integral_action_tracks_a_reference_off_the_trim_with_a_heavier_vehicle(hover, tmp_path):
    """The case that matters for integral action, over HIL (the firmware's CAN node process, the FMU, a real
    bus): the vehicle carries a payload the design does not know (1.65 kg against the 1.5 kg it was linearised
    for), starts at rest at the design's trim altitude and is asked to climb to 2.5 m, off the operating point.
    Hovering needs a throttle the operating point does not hold, sqrt(1.65 g / k_T) = 0.736 against
    u_op = 0.700 (the FMU's own physics, computed here). The LQI design (backcalc anti-windup) settles on
    2.5 m within 1 mm and its throttle on the heavier vehicle's hover throttle; the float64 twin (the law on a
    second, equally heavy FMU) agrees to float32 accuracy. A regulator about the same point cannot: at rest
    its command is u_op - K xh, a trim error it can only hold with an altitude error (law_equilibrium)."""
    from gainlink.laws import design as design_spec
    from gainlink.spec import parse_spec

    spec = tomllib.loads(hover["spec"].read_text())
    spec["integral"] = {"outputs": ["z"], "Q_diag": [4.0]}
    spec["limits"]["anti_windup"] = "backcalc"
    art = tmp_path / "lqi.json"
    art.write_text(render(seal(design_spec(parse_spec(spec)).artifact)))
    a = load(art)
    assert a.q == 1 and a.u_op.tolist() == [hover["u_hover"]] and a.y_op.tolist() == [Z_SET]

    par, mass, z_ref = hover["par"], 1.1 * hover["par"]["mass"], Z_SET + 0.5
    u_trim = math.sqrt(mass * par["g"] / par["k_T"])
    res = run_scenario(
        parse_scenario(
            {
                "name": "hover_lqi_payload",
                "artifact": str(art),
                "duration": 12.0,
                "mode": "lockstep",
                "controller": "firmware",
                "step_timeout": 2.0,
                "peer_timeout": 4.0,
                "twin": True,
                "plant": {"kind": "fmu", "path": str(hover["fmu"]), "outputs": ["z"], "parameters": {"mass": mass}},
                "transport": udp_transport(fd=True),
                "initial_state": {"z": Z_SET},
                "reference": {"r_z": {"kind": "step", "at": 1.0, "value": z_ref}},
            }
        )
    )
    assert res.complete and res.metrics["lost"] == 0, res.reason
    t, z, u = res.trace.t, res.trace.y[:, 0], res.trace.u[:, 0]
    assert np.all(res.trace.r[t < 1.0, 0] == Z_SET) and np.all(res.trace.r[t >= 1.0, 0] == z_ref)
    last = t >= t[-1] - 1.0
    assert np.max(np.abs(z[last] - z_ref)) < 1e-3, np.max(np.abs(z[last] - z_ref))
    assert u[-1] == pytest.approx(u_trim, abs=1e-4) and abs(u_trim - hover["u_hover"]) > 0.03
    tw = res.metrics["twin"]
    assert tw["inputs"]["throttle"]["max_du_rel"] < 1e-4 and tw["worst_dy_rel"] < 1e-4, tw
    # the regulator about the same point, at rest with the heavier vehicle's throttle: off its set point
    assert abs(law_equilibrium(json.loads(hover["artifact"].read_text()), u_rest=u_trim) - Z_SET) > 0.01
