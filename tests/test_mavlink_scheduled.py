"""The firmware's MAVLink node runs a scheduled artifact's law over its link (gainlink.hil.loop.bridge with a
MAVLink transport; firmware/apps/mavlink on gl_law.h): the tank of examples/tank_scheduled.toml, scheduled on its
measured level (and on an external signal carried after the references), swept across its envelope through the real
gainlink_mavlink process over UDP. Oracle: the scheduled float32 model (gainlink.laws.scheduled.model, bit for
bit the C) on the float32 samples the run recorded: the same commands, saturation and sigma flags. Its parameter table
holds every point's gains, and `gainlink mavlink upload` commits them all as one set
(gainlink.shipping.params, gainlink.mavlink.upload)."""

from __future__ import annotations

import dataclasses
import signal
import subprocess
import sys

import numpy as np
import pytest
from gainlink.firmware.mavlink_app import mavlink_executable
from gainlink.hil import run as hil_run
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.mavlink import upload as upload_mod
from gainlink.mavlink.params import INT32
from gainlink.mavlink.params import firmware_params as scheduled_firmware_params
from gainlink.mavlink.upload import UploadFailed, upload
from gainlink.shipping.artifact import from_dict
from schedule_cases import external_tank, tank_dict, tank_hil_scenario
from support.cli import assert_refused
from support.designs import designed
from support.mavlink import read_params, start_firmware
from support.net import udp_port
from support.status import scheduled_status

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def _designed(factory, name: str, spec: dict):
    a = from_dict(designed(spec))
    path = factory.mktemp(name) / f"{name}.json"
    a.save(path)
    return a, path


@pytest.fixture(scope="module")
def tank(tmp_path_factory):
    return _designed(tmp_path_factory, "tank", tank_dict())


def _sweep_scenario(path, **extra) -> dict:
    """tank_sweep, shortened: the level's reference climbs 0.04 -> 1 m at 0.2 m/s from t = 1 s."""
    transport = {"kind": "mavlink", "port": udp_port()}
    return tank_hil_scenario(path, name="tank_sweep_mavlink", transport=transport, **extra)


def _model_check(a, tr, S=None):
    Y, R = tr.y.astype(np.float32).astype(np.float64), tr.r.astype(np.float32).astype(np.float64)
    model = ScheduledFloat32Loop(a).run(Y, R, S)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), model.u.astype(np.float32).view(np.uint32))
    np.testing.assert_array_equal(tr.sat, model.saturated)
    status = scheduled_status(model.sigma_flags, model.fault)
    np.testing.assert_array_equal(tr.flags, status)  # from the node's HIL flags
    return model


def test_the_mavlink_node_runs_the_scheduled_law_bit_for_bit_as_sigma_crosses_the_points(tank, tmp_path):
    a, path = tank
    res = hil_run(_sweep_scenario(path), report=tmp_path / "report", plots=False)
    tr, m = res.trace, res.metrics
    assert res.complete and m["lost"] == 0 and tr.t.size == 120
    assert "law=scheduled-float32" in res.info["controller"]["ready"]
    assert "gainlink_mavlink" in res.info["controller"]["argv"][0]
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
    S = tr.s.astype(np.float32).astype(np.float64)  # the signals the run sent
    model = _model_check(a, tr, S)
    assert np.any(model.sigma_flags & 2) and tr.sigma.min() < 0.05 and tr.sigma.max() > 0.9  # clipped at both ends


def _retuned() -> dict:
    spec = tank_dict()
    spec["controller"]["bryson_y_max"] = [0.04]  # the same structure, other gains at every point
    return spec


def _two_points() -> dict:
    spec = tank_dict()
    spec["schedule"]["points"] = [0.04, 1.0]
    spec["schedule"]["plant"] = [spec["schedule"]["plant"][0], spec["schedule"]["plant"][2]]
    return spec


def _table(port: int) -> list[tuple[str, float]]:
    got = read_params(port)
    return [(k, float(got[k].value)) for k in sorted(got, key=lambda k: got[k].index)]


def _expected(a) -> list[tuple[str, float]]:
    specs = scheduled_firmware_params(a)
    return [(s.name, int(s.value) if s.ptype == INT32 else float(np.float32(s.value))) for s in specs]


def test_the_scheduled_table_holds_every_point_and_an_upload_commits_them_all_as_one_set(tank, tmp_path_factory):
    a, _ = tank
    b, _ = _designed(tmp_path_factory, "retuned", _retuned())
    _, c_path = _designed(tmp_path_factory, "two_points", _two_points())
    fw, port = start_firmware(mavlink_executable(a), None)
    try:
        assert _table(port) == _expected(a)  # every point's gains, GL_HASH the CRC-32 of the compiled tables
        url = f"udpout:127.0.0.1:{port}"
        assert_refused(("mavlink", "upload", c_path, "--connect", url), "GL_NPTS", c_path.parent)  # another N
        assert _table(port) == _expected(a)  # nothing changed
        res = upload(b, connect=url)
        assert res.committed and {ch.name.split("_")[2] for ch in res.changes} == {"0", "1", "2"}  # every point
        assert _table(port) == _expected(b)  # all points at once
        with MavlinkTransport(url=url, controller_url="", n_inputs=1, n_outputs=1, n_refs=1, ts=a.Ts) as link:
            model = ScheduledFloat32Loop(b)
            for seq, h in enumerate((0.1, 0.3, 0.6, 0.9)):  # sigma = h across the middle point
                y, r = np.array([h]), np.array([0.5])
                link.send_frames(link.encode_sample(seq=seq, y=y, r=r))
                cmd = link.receive_command(timeout=3.0)
                assert cmd is not None and np.float32(cmd.u[0]) == np.float32(model.step(y, r).u[0])
    finally:
        fw.stop()


def test_mavlink_upload_of_a_scheduled_artifact_through_a_mapping_is_refused_in_one_line(tank, tmp_path):
    _, path = tank
    (tmp_path / "map.toml").write_text('[[param]]\ngain = "u_max[0]"\nname = "MOT_MAX"\n')
    argv = (
        "mavlink",
        "upload",
        path,
        "--connect",
        f"udpout:127.0.0.1:{udp_port()}",
        "--mapping",
        tmp_path / "map.toml",
    )
    res = assert_refused(argv, "runs the scheduled-float32 law: a --mapping names one gain set", tmp_path, path.parent)
    assert res.out == "" and "nothing was changed" in res.err


def test_a_refused_scheduled_commit_is_rolled_back_and_a_committed_one_persists(tank, tmp_path_factory, monkeypatch):
    a, _ = tank
    b, _ = _designed(tmp_path_factory, "retuned", _retuned())
    exe, store = mavlink_executable(a), tmp_path_factory.mktemp("store") / "params.txt"

    def wrong_hash(art):  # the node's own check refuses the commit: the uploader must undo every staged value
        specs = scheduled_firmware_params(art)
        return tuple(s if s.name != "GL_HASH" else dataclasses.replace(s, value=int(s.value) ^ 1) for s in specs)

    fw, port = start_firmware(exe, store)
    try:
        url = f"udpout:127.0.0.1:{port}"
        with monkeypatch.context() as m:
            m.setattr(upload_mod, "firmware_params", wrong_hash)
            with pytest.raises(UploadFailed) as failed:
                upload(b, connect=url)
        assert failed.value.rolled_back and _table(port) == _expected(a)  # none of it
        assert upload(b, connect=url, persist=True).persisted
    finally:
        fw.stop()
    fw, port = start_firmware(exe, store)  # the stored set is loaded at start
    try:
        assert _table(port) == _expected(b)
    finally:
        fw.stop()


def test_firmware_run_serves_a_scheduled_artifact_over_mavlink(tank, tmp_path):
    a, path = tank
    port = udp_port()
    gainlink = [sys.executable, "-c", "import sys; from gainlink.cli import main; sys.exit(main())"]
    argv = [*gainlink, "firmware", "run", str(path), "--mavlink", f"udpin:127.0.0.1:{port}", "--param-file",
            str(tmp_path / "params.txt")]  # fmt: skip
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert b"law=scheduled-float32" in proc.stdout.readline()
        assert _table(port) == _expected(a)
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
        proc.stdout.close()
        proc.stderr.close()
