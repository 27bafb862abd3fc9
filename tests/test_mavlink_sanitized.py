"""The firmware's MAVLink app built with AddressSanitizer + UBSan, driven through every message it
handles (and garbage): no sanitizer report, a clean exit on SIGTERM, and the documented answers."""

from __future__ import annotations

import random
import socket
import subprocess

import numpy as np
import pytest
from gainlink.firmware.build import cache_root, firmware_dir
from gainlink.firmware.mavlink_app import EXECUTABLE, MavlinkFirmware
from gainlink.hil.links.base import STATUS_FAULT, STATUS_WATCHDOG
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.mavlink.link import MavLink
from gainlink.mavlink.params import REAL32, Encoding
from gainlink.mavlink.session import ParamSession
from gainlink.shipping.artifact import load
from gainlink.shipping.codegen import gain_set
from gainlink.shipping.export_c import render_export
from pymavlink.dialects.v20 import common as mavlink2
from support.cli import run_cli
from support.mavlink import retuned_pendulum
from support.net import udp_port


@pytest.fixture(scope="module")
def sanitized_exe(pend):
    """The app alone (``--target gainlink_mavlink``), sanitized, in a cached build tree of its own."""
    art = load(pend)
    bdir = cache_root().parent / "mavlink-asan" / art.sha256[:16]
    gen = bdir / "gen"
    gen.mkdir(parents=True, exist_ok=True)
    for name, text in render_export(art).items():
        if not (gen / name).is_file() or (gen / name).read_text() != text:
            (gen / name).write_text(text)
    cm = bdir / "cmake"
    steps = (
        []
        if (cm / "CMakeCache.txt").is_file()
        else [
            [
                "cmake",
                "-S",
                str(firmware_dir()),
                "-B",
                str(cm),
                f"-DGL_GAINS_DIR={gen}",
                "-DGL_TARGET=host",
                "-DGL_APPS=ON",
                "-DGL_SANITIZE=ON",
                "-DCMAKE_BUILD_TYPE=Debug",
            ]
        ]
    )
    steps.append(["cmake", "--build", str(cm), "--target", EXECUTABLE, "-j", "2"])
    for cmd in steps:
        proc = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    exe = cm / EXECUTABLE
    assert exe.is_file()
    return exe


def test_every_message_under_asan_ubsan(sanitized_exe, pend, tmp_path):
    art = load(pend)
    retuned = retuned_pendulum(tmp_path / "retuned.json")
    storage = tmp_path / "params.txt"
    port = udp_port()
    fw = MavlinkFirmware(sanitized_exe, url=f"udpin:127.0.0.1:{port}", storage=storage).start()
    try:
        # garbage, truncated frames and a foreign message first: the parser must shrug them off
        rng = random.Random(3)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as junk:
            for _ in range(200):
                junk.sendto(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300))), ("127.0.0.1", port))
            good = mavlink2.MAVLink_param_request_list_message(1, 1).pack(mavlink2.MAVLink(None))
            junk.sendto(good[:7], ("127.0.0.1", port))
            junk.sendto(b"\xfd" * 64, ("127.0.0.1", port))

        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--persist")
        assert res.code == 0, res.err
        with MavLink(f"udpout:127.0.0.1:{port}") as link:
            link.wait_heartbeat(timeout=5)
            s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE, retries=1)
            assert len(s.read_all()) == 64  # 7 header + 57 numbers of the pendulum's gl_gains_t (u_op, y_op too)
            assert s.read(["GL_NOPE", "GL_K_0_0"])[1] == {"GL_NOPE": "does not exist"}
            assert "GL_K_0_0" in s.set([("GL_K_0_0", REAL32, float("nan"))]).refused
            assert "GL_NOPE" in s.set([("GL_NOPE", REAL32, 1.0)]).unanswered
            link.send(mavlink2.MAVLink_param_request_read_message(1, 1, b"", 9999))  # index out of range
            assert s.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(0.0,)) == mavlink2.MAV_RESULT_ACCEPTED
            assert s.read(["GL_HASH"])[0]["GL_HASH"].value & 0xFFFFFFFF == gain_set(load(retuned)).crc32
            assert s.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(2.0,)) == mavlink2.MAV_RESULT_ACCEPTED
            assert s.read(["GL_HASH"])[0]["GL_HASH"].value & 0xFFFFFFFF == gain_set(art).crc32
            assert (
                s.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(7.0,)) == mavlink2.MAV_RESULT_UNSUPPORTED
            )
            assert (
                s.command(command=mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, params=(1.0,))
                == mavlink2.MAV_RESULT_UNSUPPORTED
            )
            version = s.request_message(msg_id=mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
            assert version.capabilities & mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            assert bytes(version.flight_custom_version) == art.sha256[:8].encode()
            assert version.uid == gain_set(art).crc32
            assert s.request_message(msg_id=mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT, wait=0.2, tries=1) is None

        t = MavlinkTransport(
            url=f"udpout:127.0.0.1:{port}", controller_url="", n_inputs=1, n_outputs=2, n_refs=1, ts=art.Ts
        )
        with t:
            t.send_frames(t.encode_reset(seq=1))
            assert t.receive_command(timeout=2).seq == 1
            t.send_frames(t.encode_sample(seq=2, y=np.array([np.nan, 0.0]), r=np.zeros(1)))
            c = t.receive_command(timeout=2)
            assert c.status == STATUS_FAULT and c.u[0] == 0.0  # the safe command: zero clamped into the limits
            for seq in (3, 4):  # 1 rad tilt: the estimate follows on the first step, the command saturates next
                t.send_frames(t.encode_sample(seq=seq, y=np.array([0.0, 1.0]), r=np.zeros(1)))
                c = t.receive_command(timeout=2)
            assert c.status == 0 and abs(c.u[0]) == art.u_max[0] and c.saturated[0]
            statuses = []
            for k in range(12):
                t.send_frames(t.encode_idle(seq=5 + k))
                statuses.append(t.receive_command(timeout=2).status)
            assert statuses[0] == 0 and statuses[-1] == STATUS_WATCHDOG
    finally:
        code = fw.stop()
        err = fw.stderr_text()
    assert code == 0, err
    assert "runtime error" not in err and "AddressSanitizer" not in err and "LeakSanitizer" not in err, err
    assert "parameters written to" in err and "commit refused" not in err
