"""MAVLink 2 signing between the firmware app (mavgen's C signing) and the ground tools (pymavlink's signing):
signed uploads work; unsigned, wrong-key and replayed requests are refused, counted and never applied; a plain
pymavlink connection signs as a third party; key files and SETUP_SIGNING; the persist rate limit."""

from __future__ import annotations

import re
import socket
import stat
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
from gainlink.errors import TransportError
from gainlink.firmware.mavlink_app import MavlinkFirmware
from gainlink.mavlink.link import MavLink
from gainlink.mavlink.params import Encoding
from gainlink.mavlink.session import ParamSession
from gainlink.mavlink.signing import enable, new_key, write_key
from gainlink.shipping.artifact import load
from gainlink.shipping.codegen import gain_set, payload_crc32
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2
from support.cli import assert_refused, run_cli
from support.net import udp_port

READ = {"GL_HASH", "GL_K_0_0"}


@pytest.fixture
def key_file(tmp_path):
    return write_key(tmp_path / "vehicle.key", new_key())


def start(mavlink_exe, key_file=None, storage=None) -> tuple[MavlinkFirmware, str]:
    port = udp_port()
    fw = MavlinkFirmware(mavlink_exe, url=f"udpin:127.0.0.1:{port}", storage=storage, signing_key=key_file)
    fw.start()
    return fw, f"udpout:127.0.0.1:{port}"


def params(url: str, key: bytes | None) -> dict:
    with MavLink(url, signing_key=key) as link:
        link.wait_heartbeat(timeout=5)
        s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE)
        return {n: v.value for n, v in s.read(sorted(READ))[0].items()}


def crc_of(art) -> int:
    return gain_set(art).crc32


def test_signed_upload_works_and_unsigned_upload_is_refused(mavlink_exe, pend, retuned, key_file, tmp_path):
    old, new = load(pend), load(retuned)
    fw, url = start(mavlink_exe, key_file, storage=tmp_path / "params.txt")
    try:
        res = run_cli("mavlink", "upload", retuned, "--connect", url, "--signing-key", key_file, "--persist")
        assert res.code == 0, res.err
        assert "gain set committed" in res.out and "persisted" in res.out
        # an upload without the key reads (open) but every set is refused: nothing changes, and it says why
        argv = ("mavlink", "upload", pend, "--connect", url, "--retries", "1", "--timeout", "0.1")
        res = assert_refused(argv, "the vehicle requires MAVLink 2 signing", tmp_path)
        got = params(url, bytes.fromhex(key_file.read_text()))
    finally:
        fw.stop()
    assert res.err == (
        "gainlink: error: vehicle 1/1 (MAV_AUTOPILOT_GENERIC, sent no AUTOPILOT_VERSION): the vehicle requires "
        "MAVLink 2 signing (--signing-key): it ignored every unsigned parameter set (its own messages are signed); "
        "nothing was changed\n"
    )
    assert got["GL_HASH"] & 0xFFFFFFFF == crc_of(new) != crc_of(old)
    assert got["GL_K_0_0"] == gain_set(new).fields["K"].reshape(-1)[0] != gain_set(old).fields["K"].reshape(-1)[0]
    c = fw.counters()
    assert c["signing"] == 1 and c["commits"] == 1 and c["persist_writes"] == 1
    assert c["unsigned"] >= 2  # the refused PARAM_SETs (sent and re-sent) are counted
    assert c["bad_frames"] >= c["unsigned"] + c["bad_signature"] + c["replayed"]


def test_wrong_key_and_replayed_frames_are_refused_and_counted(mavlink_exe, pend, key_file):
    art = load(pend)
    key = bytes.fromhex(key_file.read_text())
    name, value, commit, _ = _retune(art)
    fw, url = start(mavlink_exe, key_file)
    try:
        wrong, right = (mavlink2.MAVLink(None, srcSystem=255, srcComponent=190) for _ in range(2))
        enable(wrong, new_key(), link_id=3)
        enable(right, key, link_id=4)
        forged = [
            wrong.param_set_encode(1, 1, name.encode(), value, 9).pack(wrong),
            wrong.param_set_encode(1, 1, b"GL_HASH", commit, 6).pack(wrong),
        ]
        legit = right.param_set_encode(1, 1, name.encode(), value, 9).pack(right)
        dest = ("127.0.0.1", int(url.rsplit(":", 1)[1]))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for frame in forged:
                sock.sendto(frame, dest)
            sock.sendto(legit, dest)  # accepted once: stages the value (no commit)
            for _ in range(5):
                sock.sendto(legit, dest)  # the same bytes again: replays
        got = params(url, key)
    finally:
        fw.stop()
    assert got["GL_HASH"] & 0xFFFFFFFF == crc_of(art)  # nothing committed
    assert got["GL_K_0_0"] == pytest.approx(value)  # the one legitimate set was staged
    c = fw.counters()
    assert c["bad_signature"] == 2 and c["replayed"] == 5 and c["commits"] == 0


def test_pymavlink_signs_as_a_third_party_and_the_answers_are_signed(
    mavlink_exe, pend, key_file, tmp_path, monkeypatch
):
    """A plain pymavlink connection with its own setup_signing (not gainlink's link) sets, commits and
    persists; the firmware's answers carry valid signatures."""
    art = load(pend)
    key = bytes.fromhex(key_file.read_text())
    name, value, commit, _ = _retune(art)
    fw, url = start(mavlink_exe, key_file, storage=tmp_path / "params.txt")
    monkeypatch.setenv("MAVLINK20", "1")  # pymavlink's own switch to MAVLink 2 (signing needs it)
    try:
        conn = mavutil.mavlink_connection(url, source_system=250, source_component=190, dialect="common")
        conn.setup_signing(key, sign_outgoing=True, link_id=7)
        conn.mav.heartbeat_send(6, 8, 0, 0, 0)
        hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
        assert hb is not None and hb.get_signed()
        conn.mav.param_set_send(1, 1, name.encode(), value, 9)
        echo = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=3)
        assert echo is not None and echo.get_signed() and echo.param_value == pytest.approx(value)
        conn.mav.param_set_send(1, 1, b"GL_HASH", commit, 6)
        echo = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=3)
        assert echo is not None and echo.param_id == "GL_HASH"
        conn.mav.command_long_send(1, 1, mavlink2.MAV_CMD_PREFLIGHT_STORAGE, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
        assert ack is not None and ack.get_signed() and ack.result == mavlink2.MAV_RESULT_ACCEPTED
        conn.close()
    finally:
        fw.stop()
    assert fw.counters()["commits"] == 1 and fw.counters()["persist_writes"] == 1


def test_setup_signing_replaces_the_key_only_when_signed(mavlink_exe, pend, key_file):
    key, rotated = bytes.fromhex(key_file.read_text()), new_key()
    fw, url = start(mavlink_exe, key_file)
    try:
        with MavLink(url) as unsigned:  # unsigned SETUP_SIGNING: refused (as any unsigned command)
            unsigned.wait_heartbeat(timeout=5)
            unsigned.send(mavlink2.MAVLink_setup_signing_message(1, 1, list(new_key()), 1))
        with MavLink(url, signing_key=key) as link:
            link.wait_heartbeat(timeout=5)
            link.send(mavlink2.MAVLink_setup_signing_message(1, 1, list(rotated), 0))
        assert params(url, rotated)["GL_HASH"] & 0xFFFFFFFF == crc_of(load(pend))
        with pytest.raises(TransportError, match="does not sign with this key"):
            params(url, key)
    finally:
        fw.stop()
    assert bytes.fromhex(key_file.read_text()) == rotated  # kept for the next start
    assert stat.S_IMODE(key_file.stat().st_mode) == 0o600
    assert fw.counters()["unsigned"] >= 1


def test_udp_without_a_key_refuses_setup_signing(mavlink_exe):
    fw, url = start(mavlink_exe)
    try:
        with MavLink(url) as link:
            link.wait_heartbeat(timeout=5)
            link.send(mavlink2.MAVLink_setup_signing_message(1, 1, list(new_key()), 1))
        params(url, None)  # still unsigned: the key was not taken
    finally:
        fw.stop()
    c = fw.counters()
    assert c["setup_refused"] == 1 and c["signing"] == 0


def test_persist_writes_only_changes_and_at_most_four_at_once(mavlink_exe, pend, key_file, tmp_path):
    """Flash wear: a persist of the set storage already holds writes nothing; at most 4 writes in a burst."""
    art = load(pend)
    key = bytes.fromhex(key_file.read_text())
    fw, url = start(mavlink_exe, key_file, storage=tmp_path / "params.txt")
    results = []
    try:
        with MavLink(url, signing_key=key) as link:
            link.wait_heartbeat(timeout=5)
            s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE)

            def commit_and_persist(factor: float | None) -> None:
                if factor is not None:
                    name, value, _, crc = _retune(art, factor=factor, avoid_nan=False)
                    out = s.set([(name, 9, value), ("GL_HASH", 6, struct.unpack("<i", struct.pack("<I", crc))[0])])
                    assert out.ok, out
                results.append(s.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(1,)))

            for factor in (1.01, 1.02, 1.01, 1.02):
                commit_and_persist(factor)  # four different sets in a row: four writes
            commit_and_persist(None)  # storage already holds this one: accepted, no write
            commit_and_persist(1.01)  # a fifth write within the minute: refused
    finally:
        fw.stop()
    ok, later = mavlink2.MAV_RESULT_ACCEPTED, mavlink2.MAV_RESULT_TEMPORARILY_REJECTED
    assert results == [ok] * 5 + [later]
    c = fw.counters()
    assert (c["persist_writes"], c["persist_skipped"], c["persist_limited"], c["commits"]) == (4, 1, 1, 5)


@pytest.fixture(scope="module")
def clock_shift(tmp_path_factory) -> Path:
    """tests/clock_shift.c built as an LD_PRELOAD library (see its header)."""
    src = Path(__file__).with_name("clock_shift.c")
    out = tmp_path_factory.mktemp("clock_shift") / "libclock_shift.so"
    subprocess.run(
        ["cc", "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(out), str(src), "-ldl"],
        check=True,
        capture_output=True,
    )
    return out


def test_persist_rate_limit_refills_one_write_a_minute_up_to_four(
    mavlink_exe, pend, clock_shift, tmp_path, monkeypatch
):
    """The persist rate limit's refill, on the real app process over UDP, without waiting in wall time: the app
    takes its time from CLOCK_MONOTONIC, which tests/clock_shift.c (LD_PRELOAD) holds still and moves forward by
    what the test writes into a file, so how long the test takes does not count; nothing in the firmware changes
    for the test. gl_mav_node.h: at most 4 writes in a
    burst, then one per minute (GL_MAV_PERSIST_PERIOD_US), a full bucket banks no time. So: 4 writes, the 5th
    refused; 45 s later still refused; a minute after the burst began one write, and only one; ten minutes on
    the bucket holds 4 again, not 10."""
    art = load(pend)
    shift = tmp_path / "clock_shift_us"
    shift.write_bytes(struct.pack("=q", 0))
    monkeypatch.setenv("LD_PRELOAD", str(clock_shift))
    monkeypatch.setenv("GL_CLOCK_SHIFT_FILE", str(shift))
    fw, url = start(mavlink_exe, storage=tmp_path / "params.txt")
    monkeypatch.delenv("LD_PRELOAD")
    factors = iter(1.0 + 0.01 * i for i in range(1, 20))  # every set new: no persist is skipped as a repeat
    try:
        with MavLink(url) as link:
            link.wait_heartbeat(timeout=5)
            s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE)

            def commit_and_persist() -> int:
                name, value, _, crc = _retune(art, factor=next(factors), avoid_nan=False)
                out = s.set([(name, 9, value), ("GL_HASH", 6, struct.unpack("<i", struct.pack("<I", crc))[0])])
                assert out.ok, out
                return s.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(1,))

            def move_clock(seconds: float) -> None:  # in place: the app has the file mapped
                with shift.open("r+b") as f:
                    f.write(struct.pack("=q", int(seconds * 1e6)))

            burst = [commit_and_persist() for _ in range(5)]
            move_clock(45.0)  # the refill is due 60 s after the burst's first write: the app's clock stands still
            early = commit_and_persist()
            move_clock(61.0)
            refill = [commit_and_persist() for _ in range(2)]
            move_clock(661.0)
            after_ten_minutes = [commit_and_persist() for _ in range(5)]
    finally:
        fw.stop()
    ok, later = mavlink2.MAV_RESULT_ACCEPTED, mavlink2.MAV_RESULT_TEMPORARILY_REJECTED
    assert burst == [ok] * 4 + [later]
    assert early == later
    assert refill == [ok, later]
    assert after_ten_minutes == [ok] * 4 + [later]
    c = fw.counters()
    assert (c["persist_writes"], c["persist_limited"], c["commits"]) == (9, 4, 13), c
    waits = [int(w) for w in re.findall(r"next write in (\d+) s", fw.stderr_text())]
    # to the second: 60 s after the burst, 15 s left at 45 s, 59 s after the refill at 61 s, a full bucket's 60 s
    assert waits == [60, 15, 59, 60], waits


def test_key_file_errors_are_one_line(tmp_path, pend, mavlink_exe):
    bad = tmp_path / "bad.key"
    for content in ("", "abc", "zz" * 32, "00" * 31, "00" * 33):
        bad.write_text(content)
        for argv in (
            ("mavlink", "upload", pend, "--connect", "udpout:127.0.0.1:9", "--signing-key", bad),
            ("mavlink", "params", "--connect", "udpout:127.0.0.1:9", "--signing-key", bad),
            ("mavlink", "setup-signing", bad, "--connect", "udpout:127.0.0.1:9"),
            ("firmware", "run", pend, "--mavlink", "udpin:127.0.0.1:9", "--signing-key", bad),
        ):
            assert_refused(argv, "64 hex digits", tmp_path)
    none = ("mavlink", "upload", pend, "--connect", "udpout:127.0.0.1:9", "--signing-key", tmp_path / "none")
    assert_refused(none, "not found", tmp_path)
    bad.write_text("00" * 31)
    app = [mavlink_exe, "--url", "udpin:127.0.0.1:0", "--signing-key", bad]
    assert_refused(app, "hex digits", tmp_path, process=True, prefix="")


def test_keygen_writes_a_private_key_and_never_replaces_one(tmp_path):
    out = tmp_path / "k.key"
    res = run_cli("mavlink", "keygen", out)
    assert res.code == 0, res.err
    assert len(bytes.fromhex(out.read_text())) == 32 and stat.S_IMODE(out.stat().st_mode) == 0o600
    assert_refused(("mavlink", "keygen", out), "exists", tmp_path)


def _retune(art, *, factor: float = 1.1, avoid_nan: bool = True) -> tuple[str, float, float, int]:
    """GL_K_0_0 scaled by ``factor``, the GL_HASH value (bytewise INT32 as a float) that commits it, and that CRC.

    With ``avoid_nan`` the factor is nudged until the CRC's bytes are not a NaN pattern as a float32 (which a
    Python float could alter on its way into pymavlink's PARAM_SET)."""
    g = gain_set(art)
    fields = {k: np.array(v, dtype=np.float32, copy=True) for k, v in g.fields.items()}
    fields["K"].reshape(-1)[0] *= np.float32(factor)
    crc = payload_crc32(header=g.header, fields=fields)
    (as_float,) = struct.unpack("<f", struct.pack("<I", crc))
    if avoid_nan and np.isnan(as_float):
        return _retune(art, factor=factor * 1.01)
    return "GL_K_0_0", float(fields["K"].reshape(-1)[0]), as_float, crc
