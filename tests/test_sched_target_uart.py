"""The Cortex-M4F image of a scheduled export serves its scheduled law on its UART: the slcan and MAVLink nodes
(firmware/ports/cortex-m/cortex-m.cmake, main.c `serve ...`) run gl_sched_step, as the host apps do.

The tank of examples/tank_scheduled.toml in closed loop in QEMU on mps2-an386 (HIL, controller = "qemu"), its level
swept across the envelope; over MAVLink also the tank scheduled on an external signal, which the HIL sample carries
after the references. Oracles: the host app of the same export on the same scenario (the same closed loop bit for
bit), and the scheduled float32 model (gainlink.laws.scheduled.model) on the samples the image received:
commands, saturation and sigma flags (from the node's status bits). A retuned schedule uploaded to the image's
MAVLink node (every point's gains as one set, `gainlink mavlink upload --persist`) runs bit for bit the retuned model
and comes back from the image's flash after a restart; a commit the image refuses is rolled back, point by point."""

from __future__ import annotations

import dataclasses
import json
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from gainlink.errors import FirmwareError
from gainlink.firmware.build import build
from gainlink.firmware.uart import QemuUart
from gainlink.hil import run as hil_run
from gainlink.hil.links.can import CanTransport
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.mavlink import upload as upload_mod
from gainlink.mavlink.params import INT32, table_hash
from gainlink.mavlink.params import firmware_params as scheduled_firmware_params
from gainlink.mavlink.upload import UploadFailed, upload
from gainlink.shipping.artifact import from_dict
from schedule_cases import external_tank, tank_dict, tank_hil_scenario
from support.cli import run_cli
from support.designs import designed
from support.hil import udp_transport
from support.mavlink import read_params
from support.net import tcp_port, udp_port
from support.status import scheduled_status

# one worker runs the module (24 CPU-s: the images built, QEMU): started first
pytestmark = [
    pytest.mark.usefixtures("quiet_design_warnings"),
    pytest.mark.xdist_group("test_sched_target_uart"),
    pytest.mark.slow(cpu=24),
]

BOARD = "mps2-an386"


def _saved(spec: dict, tmp):
    a = from_dict(designed(spec))
    path = tmp / "gains.json"
    a.save(path)
    build(a, target="cortex-m4", board=BOARD)  # the serving image, built once
    return a, path


@pytest.fixture(scope="module")
def level(tmp_path_factory):
    """The example tank on its measured level, saved, its serving image built."""
    return _saved(tank_dict(), tmp_path_factory.mktemp("level"))


@pytest.fixture(scope="module")
def external(tmp_path_factory):
    """The tank on an external sigma ``load``, saved, its serving image built."""
    return _saved(external_tank(), tmp_path_factory.mktemp("external"))


def _sweep(path, transport: dict, *, controller: str, **extra) -> dict:
    """The level's reference climbs 0.04 -> 1 m at 0.4 m/s from t = 0.5 s, in lockstep (80 steps)."""
    data = {"duration": 4.0, "controller": controller, "peer_timeout": 5.0}
    if controller == "qemu":
        data["board"] = BOARD
    return tank_hil_scenario(path, name="tank_sweep_uart", transport=transport, rate=0.4, start=0.5, **(data | extra))


def _assert_model(a, res, S=None) -> None:
    """The image's commands, saturation and sigma flags are the scheduled float32 model's on its samples."""
    tr = res.trace
    assert res.complete and res.metrics["lost"] == 0 and tr.got.all()
    Y, R = tr.y.astype(np.float32).astype(np.float64), tr.r.astype(np.float32).astype(np.float64)
    model = ScheduledFloat32Loop(a).run(Y, R, S)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), model.u.astype(np.float32).view(np.uint32))
    np.testing.assert_array_equal(tr.sat, model.saturated)
    np.testing.assert_array_equal(tr.flags, scheduled_status(model.sigma_flags, model.fault))


def _assert_same(image, host) -> None:
    np.testing.assert_array_equal(image.trace.u, host.trace.u)
    np.testing.assert_array_equal(image.trace.y, host.trace.y)
    np.testing.assert_array_equal(image.trace.flags, host.trace.flags)


def test_the_images_slcan_node_runs_the_scheduled_law_bit_for_bit(level):
    a, path = level
    slcan = {"interface": "slcan", "channel": f"socket://127.0.0.1:{tcp_port()}"}
    image = hil_run(_sweep(path, slcan, controller="qemu"))
    ready = image.info["controller"]["ready"]
    assert ready.startswith(f"gainlink tank_scheduled {BOARD} sha256:{a.sha256} law=scheduled-float32 variant=unrolled")
    assert ready.endswith("ready slcan encoding=float32 law=scheduled-float32 wire=4")
    _assert_model(a, image)
    assert image.trace.sigma.min() < 0.05 and image.trace.sigma.max() > 0.8  # across the middle point
    host = hil_run(_sweep(path, udp_transport(fd=False), controller="firmware"))
    _assert_same(image, host)


def test_the_images_mavlink_node_runs_the_scheduled_law_on_an_external_sigma(external):
    a, path = external
    signal = {"kind": "sweep", "low": 0.0, "high": 1.2, "rate": 0.4, "start": 0.5}
    mav = {"kind": "mavlink", "url": f"tcp:127.0.0.1:{tcp_port()}"}
    image = hil_run(_sweep(path, mav, controller="qemu", schedule_signal={"load": signal}))
    assert "law=scheduled-float32" in image.info["controller"]["ready"]
    S = image.trace.s.astype(np.float32).astype(np.float64)  # the signals the run sent
    _assert_model(a, image, S)
    assert np.any(image.trace.flags & 0x20)  # clipped at 0 and above 1.0: from the node
    host = hil_run(_sweep(path, {"kind": "mavlink", "port": udp_port()}, controller="firmware",
                          schedule_signal={"load": signal}))  # fmt: skip
    _assert_same(image, host)


def test_the_microbit_serves_no_scheduled_law_and_says_so(level):
    """Its 16 KiB of RAM hold no bus node beside a scheduled law: one line, before QEMU starts."""
    _, path = level
    slcan = {"interface": "slcan", "channel": "socket://127.0.0.1:1"}
    with pytest.raises(FirmwareError, match=r"microbit image carries no bus node for this artifact") as exc:
        hil_run(_sweep(path, slcan, controller="qemu") | {"board": "microbit"})
    assert "\n" not in str(exc.value)


def test_firmware_run_serves_the_scheduled_law_over_slcan_from_the_image(level, tmp_path):
    """``gainlink firmware run --target cortex-m4 --can SLCAN`` of a scheduled artifact: the image's node answers
    the scheduled float32 model's commands as sigma moves across the middle point."""
    a, path = level
    cfg = {"interface": "slcan", "channel": f"socket://127.0.0.1:{tcp_port()}"}
    gainlink = [sys.executable, "-c", "import sys; from gainlink.cli import main; sys.exit(main())"]
    argv = [*gainlink, "firmware", "run", str(path), "--target", "cortex-m4", "--can", json.dumps(cfg),
            "--flash-dir", str(tmp_path / "flash")]  # fmt: skip
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    transport = CanTransport(cfg, artifact=a)
    model = ScheduledFloat32Loop(a)
    try:
        assert b"law=scheduled-float32" in proc.stdout.readline()
        transport.open()
        for seq, h in ((3, 0.1), (4, 0.3), (5, 0.6)):
            y, r = np.array([h]), np.array([0.5])
            transport.send_frames(transport.encode_sample(seq=seq, y=y, r=r))
            cmd = transport.receive_command(timeout=5.0)
            assert cmd is not None and cmd.seq == seq
            assert np.float32(cmd.u[0]).view(np.uint32) == np.float32(model.step(y, r).u[0]).view(np.uint32)
    finally:
        transport.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        proc.stdout.close()
        proc.stderr.close()


# -- a retuned schedule uploaded to the image's MAVLink node ---------------------------------------------------------


@pytest.fixture(scope="module")
def retuned(tmp_path_factory):
    """The example tank designed again with a tighter level weight: the same points and structure, other gains at
    every point (as tests/test_mavlink_scheduled.py uploads to the host app)."""
    spec = tank_dict()
    spec["controller"]["bryson_y_max"] = [0.04]
    a = from_dict(designed(spec))
    path = tmp_path_factory.mktemp("retuned") / "retuned.json"
    a.save(path)
    return a, path


def _mav_image(a, flash) -> QemuUart:
    elf = build(a, target="cortex-m4", board=BOARD).files["elf"]  # cached: the module's serving image
    return QemuUart(elf, board=BOARD, protocol="mavlink", port=tcp_port(), flash_dir=flash, lifetime_s=300)


def _table(url: str) -> list[tuple[str, float]]:
    got = read_params(url)
    return [(k, float(got[k].value)) for k in sorted(got, key=lambda k: got[k].index)]


def _expected(a) -> list[tuple[str, float]]:
    specs = scheduled_firmware_params(a)
    return [(s.name, int(s.value) if s.ptype == INT32 else float(np.float32(s.value))) for s in specs]


UPLOAD_TIMEOUT = 1.0  # s before a request is re-sent (10 retries): generous, a loaded machine stalls QEMU
LEVELS = np.concatenate([np.linspace(0.05, 0.95, 30), np.linspace(0.95, 0.2, 15)])  # sigma = h across the points


def _image_u(url: str, a) -> np.ndarray:
    """The image's float32 commands for the levels LEVELS (reference 0.5 m) after a reset of its loop."""
    link = MavlinkTransport(url=url, controller_url="", n_inputs=a.m, n_outputs=a.p, n_refs=a.q, ts=a.Ts)
    U = np.zeros((LEVELS.size, a.m), dtype=np.float32)
    with link:
        link.send_frames(link.encode_reset(seq=0))
        assert link.receive_command(timeout=15.0) is not None  # generous: a loaded VM stalls QEMU
        for k, h in enumerate(LEVELS):
            link.send_frames(link.encode_sample(seq=k + 1, y=np.array([h]), r=np.array([0.5])))
            cmd = link.receive_command(timeout=15.0)
            assert cmd is not None and cmd.seq == k + 1, k
            U[k] = cmd.u
    return U


def _model_u(a) -> np.ndarray:
    Y = LEVELS.astype(np.float32).astype(np.float64)[:, None]
    return ScheduledFloat32Loop(a).run(Y, np.full((LEVELS.size, 1), 0.5)).u.astype(np.float32)


def _wrong_hash(art):
    """The retuned set with a GL_HASH one bit off: the image's own check (the tables' CRC) refuses the commit."""
    specs = scheduled_firmware_params(art)
    return tuple(s if s.name != "GL_HASH" else dataclasses.replace(s, value=int(s.value) ^ 1) for s in specs)


def test_a_retuned_schedule_uploaded_to_the_images_mavlink_node_commits_runs_bit_for_bit_and_survives_a_restart(
    level, retuned, tmp_path, monkeypatch
):
    (old, _), (new, new_path) = level, retuned
    assert _expected(new) != _expected(old)
    flash = tmp_path / "flash"
    with _mav_image(old, flash) as image:
        want = f"crc32={table_hash(old) & 0xFFFFFFFF} signing=off law=scheduled-float32 wire=4"
        assert image.ready_line.endswith(want), image.ready_line
        assert _table(image.url) == _expected(old)
        with monkeypatch.context() as m:  # a commit the image refuses: every staged value is undone, none kept
            m.setattr(upload_mod, "firmware_params", _wrong_hash)
            with pytest.raises(UploadFailed) as failed:
                upload(new, connect=image.url, persist=True, timeout=UPLOAD_TIMEOUT)
        assert failed.value.rolled_back and _table(image.url) == _expected(old)
        assert not (flash / "gl_flash.txt").exists()
        t0 = time.monotonic()
        res = run_cli("mavlink", "upload", new_path, "--connect", image.url, "--persist", "--timeout", UPLOAD_TIMEOUT)
        took = time.monotonic() - t0
        assert res.code == 0, res.err
        assert "gain set committed" in res.out and "persisted" in res.out, res.out
        changed = re.findall(r"^GL_\w+ .* -> \S+$", res.out, re.M)
        print(f"scheduled upload to the M4 image: {len(changed)} of {len(_expected(new))} parameters, {took:.2f} s")
        assert {c.split()[0].split("_")[2] for c in changed if c.startswith(("GL_KX_", "GL_KZ_"))} == {"0", "1", "2"}
        assert _table(image.url) == _expected(new)  # every point's gains at once
        u = _image_u(image.url, new)
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(new).view(np.uint32))
        assert np.any(u != _model_u(old))  # really the retuned gains
    assert (flash / "gl_flash.txt").is_file()

    with _mav_image(old, flash) as image:  # the board powered again: the retuned set comes back from flash
        assert f"crc32={table_hash(new) & 0xFFFFFFFF} " in image.ready_line, image.ready_line
        res = run_cli("mavlink", "upload", new_path, "--connect", image.url, "--dry-run", "--timeout", UPLOAD_TIMEOUT)
        assert res.code == 0 and "dry run: 0 parameter(s) would change" in res.out, res.out + res.err
        u = _image_u(image.url, new)
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(new).view(np.uint32))
