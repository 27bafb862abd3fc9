"""The firmware's MAVLink node runs a scheduled artifact's law over its link (gainlink.hil.loop.can_scheduled with a
MAVLink transport; firmware/apps/mavlink/gl_mav_law.h): the tank of examples/tank_scheduled.toml, scheduled on its
measured level (and on an external signal carried after the references), swept across its envelope through the real
gainlink_mavlink process over UDP. Oracle: the scheduled float32 model (gainlink.proof.scheduled_float32, bit for
bit the C) on the float32 samples the run recorded: the same commands, saturation and sigma flags."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from gainlink.firmware.mavlink_app import mavlink_executable
from gainlink.hil import run as hil_run
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.hil.loop.sil_scheduled import external_signals
from gainlink.mavlink.link import MavLink
from gainlink.mavlink.params import INT32, Encoding
from gainlink.mavlink.session import ParamSession
from gainlink.proof.scheduled_float32 import ScheduledFloat32Loop
from gainlink.shipping.artifact import from_dict
from gainlink.shipping.codegen_scheduled import tables
from gainlink.spec import parse_spec
from gainlink.synthesis import synthesize
from schedule_cases import external_tank, tank_dict
from support.cli import run_cli
from support.mavlink import read_params, start_firmware
from support.net import udp_port
from support.shared import once_per_run

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def _designed(factory, name: str, spec: dict):
    a = from_dict(once_per_run(factory, f"mav_sched_{name}", lambda: synthesize(parse_spec(spec)).artifact))
    path = factory.mktemp(name) / f"{name}.json"
    a.save(path)
    return a, path


@pytest.fixture(scope="module")
def tank(tmp_path_factory):
    return _designed(tmp_path_factory, "tank", tank_dict())


def _sweep_scenario(path, **extra) -> dict:
    """tank_sweep, shortened: the level's reference climbs 0.04 -> 1 m at 0.2 m/s from t = 1 s."""
    data: dict = {
        "name": "tank_sweep_mavlink",
        "artifact": str(path),
        "duration": 6.0,
        "controller": "firmware",
        "step_timeout": 2.0,
        "peer_timeout": 4.0,
        "plant": {"kind": "tank", "step": 0.005},
        "transport": {"kind": "mavlink", "port": udp_port()},
        "initial_state": {"q": 0.08, "h": 0.04},
        "reference": {"r_h": {"kind": "sweep", "low": 0.04, "high": 1.0, "rate": 0.2, "start": 1.0}},
    }
    return data | extra


def _model_check(a, tr, S=None):
    Y, R = tr.y.astype(np.float32).astype(np.float64), tr.r.astype(np.float32).astype(np.float64)
    model = ScheduledFloat32Loop(a).run(Y, R, S)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), model.u.astype(np.float32).view(np.uint32))
    np.testing.assert_array_equal(tr.sat, model.saturated)
    np.testing.assert_array_equal(tr.sigma_flags, model.sigma_flags)  # from the node's HIL flags
    return model


def test_the_mavlink_node_runs_the_scheduled_law_bit_for_bit_as_sigma_crosses_the_points(tank, tmp_path):
    a, path = tank
    res = hil_run(_sweep_scenario(path), report=tmp_path / "report", plots=False)
    tr, m = res.trace, res.metrics
    assert res.complete and m["lost"] == 0 and tr.t.size == 120
    assert "law=scheduled-float32" in res.info["controller"]["ready"]
    assert "gainlink_mavlink" in res.info["controller"]["kind"]
    assert res.info["transport"]["kind"] == "mavlink" and res.info["transport"]["commands_received"] == 120
    _model_check(a, tr)
    assert tr.sigma.min() < 0.05 and tr.sigma.max() > 0.8  # sigma moved across the middle point (0.25)
    assert m["schedule"]["sigma"] == "h"


def test_an_external_sigma_travels_after_the_references_over_mavlink(tmp_path_factory):
    a, path = _designed(tmp_path_factory, "external", external_tank())
    signal = {"kind": "sweep", "low": 0.0, "high": 1.2, "rate": 0.4, "start": 0.5}
    data = _sweep_scenario(path, schedule_signal={"load": signal}, duration=4.0)
    res = hil_run(data)
    tr = res.trace
    assert res.complete and res.metrics["lost"] == 0 and res.metrics["schedule"]["source"] == "external"
    S = external_signals(parse_scenario(data), artifact=a, t=tr.t).astype(np.float32).astype(np.float64)
    model = _model_check(a, tr, S)
    assert np.any(model.sigma_flags & 2) and tr.sigma.min() < 0.05 and tr.sigma.max() > 0.9  # clipped at both ends


def test_the_scheduled_table_is_read_only_and_its_hash_is_the_crc_of_the_compiled_tables(tank):
    a, _ = tank
    fw, port = start_firmware(mavlink_executable(a), None)
    try:
        got = read_params(port)
        with MavLink(f"udpout:127.0.0.1:{port}") as link:
            hb = link.wait_heartbeat(timeout=5)
            s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE)
            outcome = s.set([("GL_HASH", INT32, 0)])
    finally:
        fw.stop()
    assert int(hb.custom_mode) == 256  # the scheduled float32 law
    blob = b"".join(np.asarray(v, dtype="<f4").tobytes() for v in tables(a).values())
    want = {"GL_DIM_N": a.n, "GL_DIM_M": a.m, "GL_DIM_P": a.p, "GL_DIM_Q": a.q, "GL_NPTS": a.schedule.points.size}
    assert {k: int(got[k].value) for k in want} == want and int(got["GL_DIM_E"].value) == 0
    assert int(got["GL_HASH"].value) & 0xFFFFFFFF == zlib.crc32(blob) and len(got) == 7
    assert not outcome.ok and "GL_HASH" in outcome.refused  # read-only: refused, nothing changed


def test_mavlink_upload_of_a_scheduled_artifact_is_refused_in_one_line(tank):
    _, path = tank
    res = run_cli("mavlink", "upload", path, "--connect", f"udpout:127.0.0.1:{udp_port()}")
    assert res.code == 2 and res.out == ""
    assert res.err.count("\n") == 1 and "scheduled artifact" in res.err and "nothing was changed" in res.err
