"""The MAVLink app of a fixed-point export built with AddressSanitizer + UBSan, driven through its integer parameter
table (upload, refused sets, persist, reload, reset) and its HIL messages (fault, clip, watchdog): no sanitizer
report, a clean exit on SIGTERM, and the documented answers."""

from __future__ import annotations

import random
import socket
import subprocess

import numpy as np
import pytest
from gainlink.firmware.build import cache_root, firmware_dir
from gainlink.firmware.mavlink_app import EXECUTABLE, MavlinkFirmware
from gainlink.hil.links.base import STATUS_CLIPPED, STATUS_FAULT, STATUS_WATCHDOG
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.mavlink.link import MavLink
from gainlink.mavlink.params import INT32, REAL32, Encoding
from gainlink.mavlink.params import firmware_params as fixed_firmware_params
from gainlink.mavlink.session import ParamSession
from gainlink.shipping.export_c import render_export
from pymavlink.dialects.v20 import common as mavlink2
from support.cli import run_cli
from support.fixed import example, pendulum_design
from support.net import udp_port


@pytest.fixture(scope="module")
def q31_asan():
    """The q31 pendulum's app alone, sanitized, in a cached build tree of its own."""
    art = example("pendulum", "q31")
    bdir = cache_root().parent / "mavlink-asan" / art.sha256[:16]
    gen = bdir / "gen"
    gen.mkdir(parents=True, exist_ok=True)
    for name, text in render_export(art).items():
        if not (gen / name).is_file() or (gen / name).read_text() != text:
            (gen / name).write_text(text)
    cm = bdir / "cmake"
    configure = ["cmake", "-S", str(firmware_dir()), "-B", str(cm), f"-DGL_GAINS_DIR={gen}", "-DGL_TARGET=host",
                 "-DGL_APPS=ON", "-DGL_SANITIZE=ON", "-DCMAKE_BUILD_TYPE=Debug"]  # fmt: skip
    steps = [] if (cm / "CMakeCache.txt").is_file() else [configure]
    steps.append(["cmake", "--build", str(cm), "--target", EXECUTABLE, "-j", "2"])
    for cmd in steps:
        proc = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return art, cm / EXECUTABLE


def _hash(a) -> int:
    return next(int(s.value) for s in fixed_firmware_params(a) if s.name == "GL_HASH")


def _parameters(port: int, art, new) -> None:
    """Refused sets, a reload of the persisted set and a reset to the compiled one."""
    with MavLink(f"udpout:127.0.0.1:{port}") as link:
        link.wait_heartbeat(timeout=5)
        s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE, retries=1)
        assert len(s.read_all()) == len(fixed_firmware_params(art))
        assert "GL_KX_0_0" in s.set([("GL_KX_0_0", REAL32, 1.0)]).refused  # a float to an integer table
        assert "GL_FX_SIG" in s.set([("GL_FX_SIG", INT32, 5)]).refused  # read-only
        assert "GL_HASH" in s.set([("GL_HASH", INT32, 12345)]).refused  # not the staged values' CRC
        assert s.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(0.0,)) == mavlink2.MAV_RESULT_ACCEPTED
        assert s.read(["GL_HASH"])[0]["GL_HASH"].value == _hash(new)
        assert s.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(2.0,)) == mavlink2.MAV_RESULT_ACCEPTED
        assert s.read(["GL_HASH"])[0]["GL_HASH"].value == _hash(art)


def _hil(port: int, art) -> None:
    """A fault, a clipped sample and the watchdog."""
    url = f"udpout:127.0.0.1:{port}"
    t = MavlinkTransport(url=url, controller_url="", n_inputs=art.m, n_outputs=art.p, n_refs=art.q, ts=art.Ts)
    with t:
        t.send_frames(t.encode_reset(seq=1))
        assert t.receive_command(timeout=2).seq == 1
        t.send_frames(t.encode_sample(seq=2, y=np.array([np.nan, 0.0]), r=np.zeros(1)))
        assert t.receive_command(timeout=2).status == STATUS_FAULT
        t.send_frames(t.encode_sample(seq=3, y=np.array([0.0, 3.0]), r=np.zeros(1)))  # theta beyond y_max 0.5
        assert t.receive_command(timeout=2).status == STATUS_CLIPPED
        statuses = []
        for k in range(12):
            t.send_frames(t.encode_idle(seq=4 + k))
            statuses.append(t.receive_command(timeout=2).status)
        assert statuses[0] == 0 and statuses[-1] == STATUS_WATCHDOG


def test_the_fixed_point_app_under_asan_ubsan(q31_asan, tmp_path):
    art, exe = q31_asan
    new = pendulum_design("q31", [12.0, 1.0, 110.0, 1.0])
    new.save(tmp_path / "new.json")
    port = udp_port()
    fw = MavlinkFirmware(exe, url=f"udpin:127.0.0.1:{port}", storage=tmp_path / "params.txt").start()
    try:
        rng = random.Random(3)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as junk:
            for _ in range(100):
                junk.sendto(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300))), ("127.0.0.1", port))
        res = run_cli("mavlink", "upload", tmp_path / "new.json", "--connect", f"udpout:127.0.0.1:{port}", "--persist")
        assert res.code == 0, res.err
        _parameters(port, art, new)
        _hil(port, art)
    finally:
        code = fw.stop()
        err = fw.stderr_text()
    assert code == 0, err
    assert "runtime error" not in err and "AddressSanitizer" not in err and "LeakSanitizer" not in err, err
