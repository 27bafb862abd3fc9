"""The firmware's CAN node runs a scheduled artifact's law over the bus (gainlink.hil.loop.bridge): the
tank of examples/tank_scheduled.toml, scheduled on its measured level, swept across its envelope through the real
gainlink_can process on python-can udp_multicast. Oracle: the scheduled float32 model (gainlink.laws.scheduled.model,
bit for bit the C) on the float32 samples the run recorded: the same commands, saturation and sigma flags."""

from __future__ import annotations

import json
import signal
import subprocess
import sys

import numpy as np
import pytest
from gainlink.hil import run as hil_run
from gainlink.hil.links.can import CanTransport
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.shipping.artifact import from_dict
from gainlink.shipping.can_layout import layout_for
from schedule_cases import external_tank, tank_dict, tank_hil_scenario
from support.designs import designed
from support.hil import udp_transport
from support.status import scheduled_status

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def _saved(name: str, spec: dict, tmp):
    """The artifact of ``spec`` (designed once per run) and its copy ``tmp/<name>.json``."""
    a = from_dict(designed(spec))
    path = tmp / f"{name}.json"
    a.save(path)
    return a, path


@pytest.fixture(scope="module")
def tank(tmp_path_factory):
    return _saved("tank", tank_dict(), tmp_path_factory.mktemp("tank"))


def _sweep_scenario(path, **extra) -> dict:
    """tank_sweep, shortened: the level's reference climbs 0.04 -> 1 m at 0.2 m/s from t = 1 s."""
    return tank_hil_scenario(path, name="tank_sweep_can", transport=udp_transport(fd=False), **extra)


def test_the_can_node_runs_the_scheduled_law_bit_for_bit_as_sigma_crosses_the_points(tank, tmp_path):
    a, path = tank
    res = hil_run(_sweep_scenario(path), report=tmp_path / "report", plots=False)
    tr, m = res.trace, res.metrics
    assert res.complete and m["lost"] == 0 and tr.t.size == 120
    assert "law=scheduled-float32" in res.info["controller"]["ready"]
    assert res.info["transport"]["config"]["interface"] == "udp_multicast"
    Y, R = tr.y.astype(np.float32).astype(np.float64), tr.r.astype(np.float32).astype(np.float64)
    model = ScheduledFloat32Loop(a).run(Y, R)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), model.u.astype(np.float32).view(np.uint32))
    np.testing.assert_array_equal(tr.sat, model.saturated)
    status = scheduled_status(model.sigma_flags, model.fault)
    np.testing.assert_array_equal(tr.flags, status)  # from the node's status byte
    assert tr.sigma.min() < 0.05 and tr.sigma.max() > 0.8  # sigma moved across the middle point (0.25)
    assert m["schedule"]["sigma"] == "h"
    summary = (tmp_path / "report" / "summary.txt").read_text()
    assert "udp_multicast" in summary and "law=" not in summary


def test_an_external_sigma_travels_after_the_references_and_the_node_runs_on_it(tmp_path):
    a, path = _saved("external", external_tank(), tmp_path)
    layout = layout_for(a)
    assert [list(s.signals) for s in layout.measurement] == [["y_h"], ["r_h"], ["s_load"]]  # classic: one value a frame
    signal = {"kind": "sweep", "low": 0.0, "high": 1.2, "rate": 0.4, "start": 0.5}
    data = _sweep_scenario(path, schedule_signal={"load": signal}, duration=4.0)
    res = hil_run(data)
    tr = res.trace
    assert res.complete and res.metrics["lost"] == 0 and res.metrics["schedule"]["source"] == "external"
    S = tr.s.astype(np.float32).astype(np.float64)  # the signals the run sent
    Y, R = tr.y.astype(np.float32).astype(np.float64), tr.r.astype(np.float32).astype(np.float64)
    model = ScheduledFloat32Loop(a).run(Y, R, S)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), model.u.astype(np.float32).view(np.uint32))
    status = scheduled_status(model.sigma_flags, model.fault)
    np.testing.assert_array_equal(tr.flags, status)  # clipped at 0 and above 1: from the node
    assert np.any(model.sigma_flags & 2) and tr.sigma.min() < 0.05 and tr.sigma.max() > 0.9


def test_firmware_run_can_serves_a_scheduled_artifact_on_the_bus(tank, tmp_path):
    a, path = tank
    cfg = udp_transport(fd=True)
    (tmp_path / "can.json").write_text(json.dumps(cfg))
    gainlink = [sys.executable, "-c", "import sys; from gainlink.cli import main; sys.exit(main())"]
    argv = [*gainlink, "firmware", "run", str(path), "--can", str(tmp_path / "can.json")]
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    transport = CanTransport(cfg, artifact=a)
    model = ScheduledFloat32Loop(a)
    try:
        assert b"law=scheduled-float32" in proc.stdout.readline()
        transport.open()
        for seq, h in ((3, 0.1), (4, 0.3), (5, 0.6)):  # sigma = h moves across the middle point
            y, r = np.array([h]), np.array([0.5])
            transport.send_frames(transport.encode_sample(seq=seq, y=y, r=r))
            cmd = transport.receive_command(timeout=3.0)
            want = model.step(y, r)
            assert cmd is not None and cmd.seq == seq
            assert np.float32(cmd.u[0]) == np.float32(want.u[0])
    finally:
        transport.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
        proc.stdout.close()
        proc.stderr.close()
