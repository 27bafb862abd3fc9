"""The Cortex-M4F image on the bus: MAVLink and slcan on its UART under QEMU, in HIL and for gain upload.

The oracle of the HIL tests is the host build running the same scenario: the image and the host app are
compiled from the same C with -ffp-contract=off, so the same samples in give the same float32 commands out,
and the two closed loops are identical step for step. The upload test checks the loop against the float64
reference law of the artifact it uploaded; the garbage test against the image's own clean run.
"""

from __future__ import annotations

import dataclasses
import signal
import socket
import subprocess
import time

import numpy as np
import pytest
from gainlink.errors import FirmwareError, ScenarioError, TransportError
from gainlink.firmware.build import build
from gainlink.firmware.uart import QemuUart
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.report import summary_text
from gainlink.mavlink.keysetup import signing_timestamp
from gainlink.mavlink.link import MavLink
from gainlink.mavlink.params import Encoding
from gainlink.mavlink.session import ParamSession
from gainlink.mavlink.signing import enable, read_key
from gainlink.shipping.artifact import load
from gainlink.shipping.codegen import gain_set
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2
from support.cli import GAINLINK, assert_refused, run_cli
from support.hil import udp_transport
from support.mavlink import reference_u, retuned_pendulum
from support.net import tcp_port, udp_port
from support.uart import RANGES, assert_same_closed_loop, scenario


@pytest.mark.parametrize("board", ["mps2-an386", "netduinoplus2"])
def test_mavlink_on_the_uart_commands_equal_the_host_app_bit_for_bit(pend, board):
    host = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port()}, controller="firmware"))
    image = run_scenario(
        scenario(pend, {"kind": "mavlink", "url": f"tcp:127.0.0.1:{tcp_port()}"}, controller="qemu", board=board)
    )
    assert_same_closed_loop(image, host)
    assert image.info["controller"]["board"] == board
    assert image.info["controller"]["ready"].startswith(f"gainlink pendulum {board} sha256:{load(pend).sha256}")
    assert image.info["transport"]["uart"] and image.metrics["uart"]["commands"] == image.metrics["steps"]
    assert image.metrics["uart"]["round_trips_per_s"] > 0


@pytest.mark.parametrize("board,encoding", [("mps2-an386", "float32"), ("netduinoplus2", "int16")])
def test_slcan_on_the_uart_commands_equal_the_host_can_app_bit_for_bit(pend, board, encoding):
    layout = {"encoding": encoding, "ranges": RANGES} if encoding == "int16" else {}
    host = run_scenario(scenario(pend, {**udp_transport(fd=False), **layout}, controller="firmware"))
    image = run_scenario(
        scenario(
            pend,
            {"interface": "slcan", "channel": f"socket://127.0.0.1:{tcp_port()}", **layout},
            controller="qemu",
            board=board,
        )
    )
    assert_same_closed_loop(image, host)
    assert image.info["transport"]["config"]["interface"] == "slcan"
    assert image.info["transport"]["encoding"] == encoding


def test_uart_capacity_comes_from_the_service_time_of_every_answer(pend):
    """Realtime at 1 kHz over the image's UART, which cannot keep up (a 40-byte sample alone takes ~1.5 ms to
    get in): samples queue and their commands come back after the deadline. The report's "a loop up to X Hz"
    is still measured, from every answered sample's service time (its command minus the later of its send and
    the previous command), late answers included, and X is below the rate that failed. On main it counted the
    on-time commands only: n/a here, and above the run's rate when a few made it (285 Hz for a 250 Hz run that
    missed 361 of 400 deadlines). In lockstep each sample waits for the previous command, so the service time
    is the round trip: X is one over the p99 of the recorded latencies."""
    rate = 1000.0
    url = f"tcp:127.0.0.1:{tcp_port()}"
    rt = scenario(pend, {"kind": "mavlink", "url": url}, controller="qemu", board="mps2-an386", duration=3.0)
    rt = dataclasses.replace(rt, mode="realtime", period=1.0 / rate, twin=False)
    res = run_scenario(rt)
    uart, steps = res.metrics["uart"], res.metrics["steps"]
    assert res.metrics["deadline_misses"] > steps // 2, "the UART kept up with 1 kHz: no overload to measure"
    assert uart["loop_hz_p99"] is not None and uart["loop_hz_p99"] < rate, uart
    assert uart["answered"] > uart["commands"] and uart["late_answers"] > 0, uart
    assert uart["loop_hz_p99"] == pytest.approx(1e6 / uart["service_us"]["p99"])
    line = next(ln for ln in summary_text(res).splitlines() if "emulated UART" in ln)
    assert "service time" in line and "late" in line, line

    lock = run_scenario(
        scenario(pend, {"kind": "mavlink", "url": f"tcp:127.0.0.1:{tcp_port()}"}, controller="qemu", duration=0.5)
    )
    lat = lock.trace.latency_ns[lock.trace.got]
    assert lock.metrics["uart"]["answered"] == lock.metrics["steps"] == lat.size
    assert lock.metrics["uart"]["loop_hz_p99"] == pytest.approx(1e9 / np.percentile(lat, 99), rel=1e-9)


def closed_loop(url: str, art, *, steps: int = 80, garbage=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The artifact's discrete plant against the image over its UART; ``garbage(k)`` bytes go before sample k."""
    t = MavlinkTransport(url=url, controller_url="", n_inputs=art.m, n_outputs=art.p, n_refs=art.q, ts=art.Ts)
    x = np.zeros(art.n)
    x[2] = 0.05
    Y, R, U = np.zeros((steps, art.p)), np.full((steps, art.q), 0.2), np.zeros((steps, art.m))
    with t:
        t.send_frames(t.encode_reset(seq=0))
        assert t.receive_command(timeout=15.0) is not None
        u = np.zeros(art.m)
        for k in range(steps):
            Y[k] = (art.Cd @ x + art.Dd @ u).astype(np.float32)
            if garbage is not None:
                t.send_frames([garbage(k)])
            t.send_frames(t.encode_sample(seq=k + 1, y=Y[k], r=R[k]))
            c = t.receive_command(timeout=15.0)  # generous: elapses only on a real loss (a loaded VM stalls QEMU)
            assert c is not None and c.seq == k + 1, k
            u = U[k] = c.u
            x = art.Ad @ x + art.Bd @ u
    return Y, R, U


def session(url: str, key: bytes | None = None) -> tuple[MavLink, ParamSession]:
    link = MavLink(url, signing_key=key)
    link.wait_heartbeat(timeout=10)
    return link, ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE)


@pytest.fixture(scope="module")
def elf(pend):
    return build(load(pend), target="cortex-m4", board="mps2-an386").files["elf"]


def test_upload_persists_in_flash_and_survives_a_restart_of_the_image(elf, pend, tmp_path):
    old, new = load(pend), load(retuned_pendulum(tmp_path / "retuned.json"))
    flash = tmp_path / "flash"
    with QemuUart(
        elf, board="mps2-an386", protocol="mavlink", port=tcp_port(), flash_dir=flash, lifetime_s=300
    ) as image:
        Y, R, U = closed_loop(image.url, old)
        np.testing.assert_allclose(U, reference_u(old, Y, R), atol=1e-4)
        res = run_cli("mavlink", "upload", tmp_path / "retuned.json", "--connect", image.url, "--persist")
        assert res.code == 0, res.err
        assert "gain set committed" in res.out and "persisted" in res.out
        Y, R, U = closed_loop(image.url, new)
        np.testing.assert_allclose(U, reference_u(new, Y, R), atol=1e-4)
        assert np.max(np.abs(U - reference_u(old, Y, R))) > 1e-2  # really the new gains
    assert (flash / "gl_flash.txt").is_file()

    with QemuUart(
        elf, board="mps2-an386", protocol="mavlink", port=tcp_port(), flash_dir=flash, lifetime_s=300
    ) as image:  # the board powered again: the set comes back from flash, and the ready line says so
        assert f"format=float32 gains=persisted crc32={gain_set(new).crc32} " in image.ready_line, image.ready_line
        res = run_cli("mavlink", "upload", tmp_path / "retuned.json", "--connect", image.url, "--dry-run")
        assert res.code == 0 and "dry run: 0 parameter(s) would change" in res.out, res.out + res.err
        Y, R, U = closed_loop(image.url, new)
        np.testing.assert_allclose(U, reference_u(new, Y, R), atol=1e-4)
    stored = (flash / "gl_flash.txt").read_bytes()

    with QemuUart(
        elf,
        board="mps2-an386",
        protocol="mavlink",
        port=tcp_port(),
        flash_dir=flash,
        lifetime_s=300,
        options=("gains=artifact",),
    ) as image:  # started on the artifact's set: the flash keeps the persisted one
        assert f"gains=artifact crc32={gain_set(old).crc32} " in image.ready_line, image.ready_line
        link, s = session(image.url)
        with link:
            got, _ = s.read(["GL_HASH", "GL_K_0_0"])
        assert got["GL_HASH"].value & 0xFFFFFFFF == gain_set(old).crc32
        assert got["GL_K_0_0"].value == np.float32(old.K[0, 0])
    assert (flash / "gl_flash.txt").read_bytes() == stored


@pytest.mark.parametrize("from_artifact", [False, True])
def test_firmware_run_of_the_image_says_which_gain_set_runs(elf, pend, tmp_path, from_artifact):
    """`gainlink firmware run ART --target cortex-m4 --mavlink tcp:...` (the demo's last step) over a flash that
    holds a persisted set: its start-up line names that set, not the artifact's, or with --from-artifact the
    artifact's."""
    new = load(retuned_pendulum(tmp_path / "retuned.json"))
    flash = tmp_path / "flash"
    with QemuUart(elf, board="mps2-an386", protocol="mavlink", port=tcp_port(), flash_dir=flash, lifetime_s=300) as im:
        res = run_cli("mavlink", "upload", tmp_path / "retuned.json", "--connect", im.url, "--persist")
        assert res.code == 0 and "persisted" in res.out, res.err
    url = f"tcp:127.0.0.1:{tcp_port()}"
    argv = ["firmware", "run", str(pend), "--target", "cortex-m4", "--mavlink", url, "--flash-dir", str(flash)]
    proc = subprocess.Popen(
        [str(GAINLINK), *argv, *(["--from-artifact"] if from_artifact else [])],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
        proc.stdout.close()
        proc.stderr.close()
    if from_artifact:
        assert f"; runs the artifact's gain set (float32, crc32 0x{gain_set(load(pend)).crc32:08x});" in line, line
    else:
        want = f"; runs the gain set persisted by an earlier upload (float32, crc32 0x{gain_set(new).crc32:08x}), NOT"
        assert want in line, line


def request_sys_status(link: MavLink) -> object:
    link.send(
        mavlink2.MAVLink_command_long_message(
            1, 1, mavlink2.MAV_CMD_REQUEST_MESSAGE, 0, float(mavlink2.MAVLINK_MSG_ID_SYS_STATUS), 0, 0, 0, 0, 0, 0
        )
    )
    for _ in range(50):
        for m in link.poll(0.2):
            if m.get_type() == "SYS_STATUS":
                return m
    raise AssertionError("no SYS_STATUS")


def sys_status(url: str, key: bytes | None = None) -> tuple[int, object]:
    """GL_HASH and SYS_STATUS of the image (asked with signed requests when ``key`` is given)."""
    link, s = session(url, key)
    with link:
        crc = s.read(["GL_HASH"])[0]["GL_HASH"].value & 0xFFFFFFFF
        return crc, request_sys_status(link)


def status_around(url: str, key: bytes, frames: list[bytes]) -> tuple[object, object, int]:
    """SYS_STATUS before and after raw ``frames`` go to the image's UART, and GL_HASH after them (one signed
    session: the image takes the bytes in order, so the second answer has counted every frame)."""
    link, s = session(url, key)
    with link:
        before = request_sys_status(link)
        link.conn.write(b"".join(frames))
        after = request_sys_status(link)
        return before, after, s.read(["GL_HASH"])[0]["GL_HASH"].value & 0xFFFFFFFF


def test_garbage_between_frames_is_survived_counted_and_leaves_the_gains_alone(elf, pend):
    art = load(pend)
    rng = np.random.default_rng(11)
    injected = []

    def garbage(k: int) -> bytes:
        # random bytes (MAVLink start bytes among them), then enough zeros to end any bogus frame they began
        chunk = rng.integers(0, 256, size=int(rng.integers(1, 64)), dtype=np.uint8).tobytes() + bytes(280)
        injected.append(chunk)
        return chunk

    with QemuUart(elf, board="mps2-an386", protocol="mavlink", port=tcp_port(), lifetime_s=300) as image:
        crc_before, _ = sys_status(image.url)
        Y0, _, U0 = closed_loop(image.url, art)
        Y1, _, U1 = closed_loop(image.url, art, garbage=garbage)
        crc_after, status = sys_status(image.url)
        assert image.exit_status() is None
    np.testing.assert_array_equal(U1, U0)  # every sample still stepped exactly once, on the same gains
    np.testing.assert_array_equal(Y1, Y0)
    assert crc_after == crc_before == gain_set(art).crc32
    total = sum(len(c) for c in injected)
    starts = sum(c.count(0xFD) + c.count(0xFE) for c in injected)
    assert 10_000 < total < 65_535 and starts > 5
    assert status.errors_count1 == total  # bytes that were not part of an accepted frame: exactly the garbage
    assert 1 <= status.errors_comm <= starts  # bogus frames begun by a start byte, refused
    assert status.errors_count2 == 0  # no receive overrun on the UART


def _third_party_signed_request(url: str, key: bytes):
    """A plain pymavlink connection signing with pymavlink's own code asks for AUTOPILOT_VERSION; the answer."""
    conn = mavutil.mavlink_connection(url, source_system=250, source_component=190, dialect="common")
    try:
        conn.setup_signing(key, sign_outgoing=True, link_id=7)
        conn.mav.command_long_send(
            1,
            1,
            mavlink2.MAV_CMD_REQUEST_MESSAGE,
            0,
            float(mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION),
            0,
            0,
            0,
            0,
            0,
            0,
        )
        return conn.recv_match(type="AUTOPILOT_VERSION", blocking=True, timeout=15)
    finally:
        conn.close()


def _unsigned_frames() -> list[bytes]:
    """Unsigned frames that would change the image: stage, commit, persist, reset, turn signing off."""
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    return [
        m.pack(mav)
        for m in (
            mavlink2.MAVLink_param_set_message(1, 1, b"GL_K_0_0", 0.0, mavlink2.MAV_PARAM_TYPE_REAL32),
            mavlink2.MAVLink_param_set_message(1, 1, b"GL_HASH", 0.0, mavlink2.MAV_PARAM_TYPE_INT32),
            mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_PREFLIGHT_STORAGE, 0, 2, 0, 0, 0, 0, 0, 0),
            mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_PREFLIGHT_STORAGE, 0, 1, 0, 0, 0, 0, 0, 0),
            mavlink2.MAVLink_setup_signing_message(1, 1, [0] * 32, 0),
        )
    ]


def _signed_param_set_recorded_at(key: bytes, unix_time: float) -> bytes:
    """A PARAM_SET correctly signed with ``key``, with the signing timestamp of ``unix_time``."""
    recorded = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    enable(recorded, key, link_id=9)
    recorded.signing.timestamp = signing_timestamp(unix_time)
    return mavlink2.MAVLink_param_set_message(1, 1, b"GL_K_0_0", 0.0, mavlink2.MAV_PARAM_TYPE_REAL32).pack(recorded)


@pytest.mark.slow
def test_a_key_set_over_the_uart_guards_the_images_gains_and_survives_a_restart(elf, pend, tmp_path, monkeypatch):
    """The UART is the image's trusted link (a cable): `gainlink mavlink setup-signing` sends the first key in an
    unsigned SETUP_SIGNING, the image keeps it in its flash (store_key hook) and signs with it; another unsigned
    SETUP_SIGNING no longer changes it. A plain pymavlink connection signing with pymavlink's own code (a third
    party) is answered signed; a signed upload commits and persists; unsigned requests (the uploader without a
    key, and PARAM_SET / COMMAND_LONG / SETUP_SIGNING frames packed here) are refused and counted in SYS_STATUS,
    the gains and the flash untouched; after a restart the key is back and old signed frames stay refused."""
    old, new = load(pend), load(retuned_pendulum(tmp_path / "retuned.json"))
    key_file = tmp_path / "link.key"
    assert run_cli("mavlink", "keygen", key_file).code == 0
    key = read_key(key_file)
    flash = tmp_path / "flash"
    monkeypatch.setenv("MAVLINK20", "1")  # pymavlink's own switch to MAVLink 2 (signing needs it)
    with QemuUart(
        elf, board="mps2-an386", protocol="mavlink", port=tcp_port(), flash_dir=flash, lifetime_s=300
    ) as image:
        assert "signing=off" in image.ready_line
        res = run_cli("mavlink", "setup-signing", key_file, "--connect", image.url)
        assert res.code == 0 and "vehicle 1/1 signs with the key" in res.out, res.out + res.err
        assert (flash / "gl_key.bin").read_bytes() == key  # kept in the image's flash
        other = tmp_path / "other.key"
        assert run_cli("mavlink", "keygen", other).code == 0
        argv = ("mavlink", "setup-signing", other, "--connect", image.url)  # unsigned, now that it has one
        assert_refused(argv, "does not sign with the new key", tmp_path)
        assert (flash / "gl_key.bin").read_bytes() == key

        version = _third_party_signed_request(image.url, key)
        assert version is not None and version.get_signed() and version.uid == gain_set(old).crc32

        res = run_cli(
            "mavlink",
            "upload",
            tmp_path / "retuned.json",
            "--connect",
            image.url,
            "--signing-key",
            key_file,
            "--persist",
        )
        assert res.code == 0, res.out + res.err
        assert "gain set committed" in res.out and "persisted" in res.out
        stored = (flash / "gl_flash.txt").read_bytes()
        crc0, status0 = sys_status(image.url, key)
        assert crc0 == gain_set(new).crc32

        argv = ("mavlink", "upload", pend, "--connect", image.url, "--retries", "1", "--timeout", "0.5")
        # it reads (open) but every PARAM_SET is refused, and says why
        res = assert_refused(argv, "requires MAVLink 2 signing (--signing-key)", tmp_path)
        assert "nothing was changed" in res.err
        crc1, status1 = sys_status(image.url, key)
        assert crc1 == crc0 and status1.errors_comm > status0.errors_comm

        forged = _unsigned_frames()
        before, after, crc2 = status_around(image.url, key, forged)
        assert crc2 == crc0
        assert after.errors_comm - before.errors_comm == len(forged)  # each refused frame counted once
        assert after.errors_count1 - before.errors_count1 == sum(map(len, forged))  # none of their bytes used
        assert (flash / "gl_flash.txt").read_bytes() == stored and (flash / "gl_key.bin").read_bytes() == key

    # correctly signed, but recorded five minutes before the key was set: replayed as the first signed frame
    # after power-on, it must be refused although the image has no clock (its timestamp restarts from the one
    # it kept in flash, not from 0)
    replay = _signed_param_set_recorded_at(key, time.time() - 300)
    with QemuUart(
        elf, board="mps2-an386", protocol="mavlink", port=tcp_port(), flash_dir=flash, lifetime_s=300
    ) as image:  # powered again: key and gains come back from flash
        assert "signing=on" in image.ready_line and f"crc32={gain_set(new).crc32}" in image.ready_line
        link, s = session(image.url)  # unsigned: reads stay open, and nothing here moves the image's timestamp
        with link:
            link.conn.write(replay)
            staged = s.read(["GL_K_0_0"])[0]["GL_K_0_0"].value
        assert staged == float(np.float32(new.K[0, 0]))  # the replayed set was not staged
        _, since_power_on = sys_status(image.url, key)
        assert since_power_on.errors_comm == 1, since_power_on  # the replay, counted once
        res = run_cli(
            "mavlink",
            "upload",
            tmp_path / "retuned.json",
            "--connect",
            image.url,
            "--signing-key",
            key_file,
            "--dry-run",
        )
        assert res.code == 0 and "dry run: 0 parameter(s) would change" in res.out, res.out + res.err
        before, after, crc3 = status_around(image.url, key, forged[:2])
        assert crc3 == gain_set(new).crc32 and after.errors_comm - before.errors_comm == 2


def test_qemu_scenarios_refuse_mismatched_links_in_one_line(pend, pendulum_artifact, tmp_path):
    with pytest.raises(ScenarioError, match="board applies to controller"):
        scenario(pend, {"kind": "mavlink"}, controller="firmware", board="netduinoplus2")
    with pytest.raises(ScenarioError, match="board must be one of"):
        scenario(pend, {"kind": "mavlink"}, controller="qemu", board="stm32f4-discovery")
    udp = run_scenario_error(scenario(pend, {"kind": "mavlink", "port": udp_port()}, controller="qemu"))
    assert isinstance(udp, TransportError) and 'url = "tcp:HOST:PORT"' in str(udp)
    fd = run_scenario_error(
        scenario(pend, {"interface": "slcan", "channel": "socket://127.0.0.1:1", "fd": True}, controller="qemu")
    )
    assert isinstance(fd, TransportError) and "classic frames only" in str(fd)
    uart = run_scenario_error(scenario(pend, {"kind": "mavlink", "url": "tcp:127.0.0.1:1"}, controller="firmware"))
    assert isinstance(uart, TransportError) and 'needs controller = "qemu"' in str(uart)
    argv = ("firmware", "run", pendulum_artifact, "--target", "cortex-m4", "--mavlink", "udpin:127.0.0.1:1")
    assert_refused(argv, "expected tcp:HOST:PORT", tmp_path)


def run_scenario_error(sc) -> Exception:
    with pytest.raises((TransportError, FirmwareError)) as info:
        run_scenario(sc)
    return info.value


def test_the_image_refuses_bad_options_with_its_own_error_line(elf):
    image = QemuUart(elf, board="mps2-an386", protocol="slcan", port=tcp_port(), options=["bitrate=5"], lifetime_s=60)
    try:
        with pytest.raises(FirmwareError, match="refused its options: unknown slcan option"):
            image.start()
        assert image.exit_status() is not None  # QEMU stopped, not left running
    finally:
        image.close()


def test_the_images_slcan_adapter_answers_as_the_lawicel_protocol_says(elf):
    """Commands and their answers by the protocol (CR: ok, BEL: refused), through the image's real UART."""
    exchanges = [
        (b"V\r", b"V1013\r"),
        (b"N\r", b"NGL00\r"),
        (b"F\r", b"F00\r"),
        (b"Z0\r", b"\r"),
        (b"Z1\r", b"\a"),
        (b"S6\r", b"\r"),
        (b"S9\r", b"\a"),
        (b"s031C\r", b"\r"),
        (b"t1108" + b"00" * 8 + b"\r", b"\a"),  # a frame before the channel is open
        (b"O\r", b"\r"),
        (b"O\r", b"\a"),
        (b"S6\r", b"\a"),  # open twice, bit rate while open
        (b"t7FF0\r", b"z\r"),
        (b"T1FFFFFFF2ABCD\r", b"Z\r"),
        (b"r1230\r", b"z\r"),  # foreign id, extended, remote
        (b"t8000\r", b"\a"),
        (b"t1109" + b"00" * 9 + b"\r", b"\a"),
        (b"t1102AB\r", b"\a"),  # id > 0x7FF, dlc 9, short
        (b"d1108" + b"00" * 8 + b"\r", b"\a"),
        (b"X" * 40 + b"\r", b"\a"),
        (b"?\r", b"\a"),  # CAN FD, over-long, unknown
        (b"C\r", b"\r"),
    ]
    with QemuUart(elf, board="mps2-an386", protocol="slcan", port=tcp_port(), lifetime_s=120) as image:
        with socket.create_connection((image.host, image.port), timeout=10) as s:
            for sent, expected in exchanges:
                s.sendall(sent)
                got = b""
                deadline = time.monotonic() + 10  # a hang guard (recv has its own 10 s timeout)
                while len(got) < len(expected) and time.monotonic() < deadline:
                    got += s.recv(len(expected) - len(got))
                assert len(got) == len(expected), f"{sent!r}: no whole answer within 10 s (hung?): {got!r}"
                assert got == expected, (sent, got)


def test_a_signed_link_to_the_image_runs_and_unsigned_samples_are_refused(pend, elf, tmp_path):
    key_file = tmp_path / "hil.key"
    assert run_cli("mavlink", "keygen", key_file).code == 0
    res = run_scenario(
        scenario(
            pend,
            {"kind": "mavlink", "url": f"tcp:127.0.0.1:{tcp_port()}", "signing_key": str(key_file)},
            controller="qemu",
            duration=0.5,
        )
    )
    assert res.complete, res.reason
    # every answer passed the ground side's signature check (a board without a clock signs from timestamp 0
    # until it accepts a signed message, so a heartbeat sent before the first sample may be refused as too old)
    assert res.info["transport"]["signed"] and res.metrics["lost"] == 0 and res.trace.got.all()
    assert "signing=on" in res.info["controller"]["ready"]  # the key went into the image's flash
    art = load(pend)
    with QemuUart(
        elf,
        board="mps2-an386",
        protocol="mavlink",
        port=tcp_port(),
        signing_key=read_key(key_file),
        lifetime_s=120,
    ) as image:
        unsigned = MavlinkTransport(
            url=image.url, controller_url="", n_inputs=art.m, n_outputs=art.p, n_refs=art.q, ts=art.Ts
        )
        with unsigned:
            unsigned.send_frames(unsigned.encode_reset(seq=0))
            unsigned.send_frames(unsigned.encode_sample(seq=1, y=np.zeros(art.p), r=np.zeros(art.q)))
            assert unsigned.receive_command(timeout=3.0) is None  # refused, never stepped


def test_an_image_that_dies_mid_run_ends_the_run_with_its_reason(pend):
    """The board loses power at t = 0.3 s (QEMU killed): the run stops, incomplete, saying why; nothing raises."""
    res = run_scenario(
        scenario(
            pend,
            {"interface": "slcan", "channel": f"socket://127.0.0.1:{tcp_port()}"},
            controller="qemu",
            duration=1.0,
            faults=[{"kind": "crash", "start": 0.3}],
        )
    )
    assert not res.complete and "controller exited" in res.reason, res.reason
    assert 25 <= res.metrics["steps"] <= 40 and res.trace.got[:30].all()
