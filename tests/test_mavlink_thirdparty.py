"""Third-party MAVLink proof, offline: MAVSDK-Python (bundled libcmavsdk) and MAVProxy set and read gains
on the running firmware app, the parameter list reads back identically through pymavlink, MAVSDK and
MAVProxy, and the uploader works against MAVSDK acting as the vehicle (its parameter server)."""

from __future__ import annotations

import queue
import re
import struct
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import mavsdk  # the test extra (make setup) installs it
import numpy as np
import pytest
from gainlink.firmware.mavlink_app import MavlinkFirmware
from gainlink.mavlink.params import REAL32, as_int32, firmware_params
from gainlink.shipping.artifact import load
from gainlink.shipping.codegen import gain_set
from mavsdk.plugins.param import Param, ParamError
from mavsdk.plugins.param_server import ParamServer
from support.cli import GAINLINK, assert_refused, run_cli
from support.mavlink import closed_loop, read_params, reference_u, start_firmware
from support.net import udp_port
from support.vehicle import as_served, mavsdk_vehicle

MAVPROXY = Path(sys.executable).parent / "mavproxy.py"


def changed_gains(old, new) -> dict[str, float]:
    """REAL32 parameters whose value differs between two artifacts of one structure."""
    before = {s.name: s.value for s in firmware_params(old)}
    return {s.name: s.value for s in firmware_params(new) if s.ptype == REAL32 and s.value != before[s.name]}


@contextmanager
def mavsdk_ground_station(port: int):
    cfg = mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION)
    sdk = mavsdk.Mavsdk(cfg)
    try:
        assert sdk.add_any_connection(f"udpout://127.0.0.1:{port}") == mavsdk.ConnectionResult.SUCCESS
        system = sdk.first_autopilot(timeout_s=10.0)
        assert system is not None, "MAVSDK found no autopilot"
        yield Param(system)
    finally:
        sdk.destroy()
        cfg.destroy()


def test_mavsdk_reads_the_same_list_and_sets_gains_that_the_loop_then_runs(mavlink_exe, pend, retuned):
    old, new = load(pend), load(retuned)
    fw, port = start_firmware(mavlink_exe, None)
    try:
        reference = read_params(port)  # pymavlink
        with mavsdk_ground_station(port) as param:
            every = param.get_all_params()
            ints = {p.name: p.value for p in every.int_params}
            floats = {p.name: p.value for p in every.float_params}
            assert set(ints) | set(floats) == set(reference)
            for name, pv in reference.items():
                got = floats[name] if pv.ptype == REAL32 else ints[name]
                assert got == pv.value, name  # bit-identical floats, bytewise-decoded ints

            for name, value in changed_gains(old, new).items():
                param.set_param_float(name, value)
                assert param.get_param_float(name) == value
            with pytest.raises(ParamError) as refused:
                param.set_param_int("GL_DIM_N", 5)
            assert "READ_ONLY" in str(refused.value)
            assert param.get_param_int("GL_DIM_N") == old.n

            # staged only: the loop still runs the old set until the hash commits the new one
            assert param.get_param_int("GL_HASH") == as_int32(gain_set(old).crc32)
            Y, R, U = closed_loop(port, old, steps=100)
            np.testing.assert_allclose(U, reference_u(old, Y, R), atol=1e-4)
            param.set_param_int("GL_HASH", as_int32(gain_set(new).crc32))
            assert param.get_param_int("GL_HASH") == as_int32(gain_set(new).crc32)
        Y, R, U = closed_loop(port, new, steps=100)
        np.testing.assert_allclose(U, reference_u(new, Y, R), atol=1e-4)
    finally:
        fw.stop()


class MavProxy:
    """MAVProxy as a child process, driven through its stdin like a person at its prompt."""

    def __init__(self, port: int, cwd: Path):
        if not MAVPROXY.is_file():
            raise AssertionError(f"MAVProxy is not installed at {MAVPROXY}: run `make setup`")
        self.proc = subprocess.Popen(
            [
                sys.executable,
                str(MAVPROXY),
                f"--master=udpout:127.0.0.1:{port}",
                "--mav20",
                "--default-modules=param",
                "--no-state",
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            cwd=cwd,
            text=True,
            bufsize=1,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def wait_for(self, pattern: str, *, timeout: float = 20.0) -> re.Match:
        deadline = time.monotonic() + timeout
        rx = re.compile(pattern)
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                continue
            self.seen.append(line)
            m = rx.search(line)
            if m:
                return m
        raise AssertionError(f"MAVProxy never printed /{pattern}/; output:\n" + "\n".join(self.seen[-30:]))

    def command(self, text: str) -> None:
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()

    def show_all(self, expected: int) -> dict[str, float]:
        self.command("param show GL_*")
        out: dict[str, float] = {}
        while len(out) < expected:
            m = self.wait_for(r"(GL_[A-Z0-9_]+)\s+(\S+)\s*$")
            out[m.group(1)] = float(m.group(2))
        return out

    def close(self) -> None:
        try:
            self.proc.stdin.close()
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)


def float_bits_as_int32(value: float) -> int:
    return struct.unpack("<i", struct.pack("<f", value))[0]


def test_mavproxy_reads_the_same_list_and_sets_gains(mavlink_exe, pend, retuned, tmp_path):
    old, new = load(pend), load(retuned)
    fw, port = start_firmware(mavlink_exe, None)
    mp = MavProxy(port, tmp_path)
    try:
        reference = read_params(port)
        mp.wait_for(rf"Received {len(reference)} parameters")
        shown = mp.show_all(len(reference))
        assert set(shown) == set(reference)
        for name, pv in reference.items():
            if pv.ptype == REAL32:
                assert shown[name] == pv.value, name
            else:  # MAVProxy decodes bytewise integers only for PX4; the bits it shows are the same
                assert float_bits_as_int32(shown[name]) == pv.value, name

        changes = changed_gains(old, new)
        for name, value in changes.items():
            mp.command(f"param set {name} {value!r}")
        mp.command("param set GL_DIM_N 5")
        deadline = time.monotonic() + 60  # a hang guard: MAVProxy paces its sets at ~10/s
        while True:  # MAVProxy sends its sets from a queue: wait until the firmware holds them all
            after = read_params(port)
            if all(after[name].value == value for name, value in changes.items()) or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        for name, value in changes.items():
            assert after[name].value == value, f"{name}: the firmware did not get MAVProxy's set within 60 s (hung?)"
        assert after["GL_DIM_N"].value == old.n  # read-only: refused
        for name, value in changes.items():
            mp.command(f"param fetch {name}")
            mp.wait_for(rf"^{name} = ")
            mp.command(f"param show {name}")
            m = mp.wait_for(rf"{name}\s+(\S+)\s*$")
            assert float(m.group(1)) == value, name
    finally:
        mp.close()
    try:
        # the staged set MAVProxy wrote is the retuned design: the uploader has nothing left to set, only
        # the commit, and the loop then runs the retuned gains
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}")
        assert res.code == 0, res.err
        assert "1 set(s) verified" in res.out and "gain set committed" in res.out
        Y, R, U = closed_loop(port, new, steps=100)
        np.testing.assert_allclose(U, reference_u(new, Y, R), atol=1e-4)
    finally:
        fw.stop()


def test_uploader_against_mavsdk_as_the_vehicle(pend, tmp_path):
    art = load(pend)
    port = udp_port()
    mapping = tmp_path / "px4_style.toml"
    mapping.write_text(
        '[[param]]\ngain = "K[0,0]"\nname = "MC_ROLLRATE_P"\nscale = -0.1\n'
        '[[param]]\ngain = "K[0,1]"\nname = "MC_ROLLRATE_D"\nscale = -0.01\n'
        '[[param]]\ngain = "u_max[0]"\nname = "MC_ROLL_LIM"\ntype = "INT32"\nscale = 10.0\n'
        '[[param]]\ngain = "Ts"\nname = "MC_RATE_DT"\n'
    )
    cfg = mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.AUTOPILOT)
    sdk = mavsdk.Mavsdk(cfg)
    try:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == mavsdk.ConnectionResult.SUCCESS
        server = ParamServer(sdk.server_component())
        server.provide_param_float("MC_ROLLRATE_P", 0.15)
        server.provide_param_float("MC_ROLLRATE_D", 0.003)
        server.provide_param_int("MC_ROLL_LIM", 7)
        server.provide_param_float("MC_RATE_DT", 0.004)
        server.provide_param_float("MC_OTHER", 1.0)

        res = run_cli("mavlink", "upload", pend, "--connect", f"udpout:127.0.0.1:{port}", "--mapping", mapping)
        assert res.code == 0, res.err
        assert "4 set(s) verified" in res.out
        assert server.retrieve_param_float("MC_ROLLRATE_P") == np.float32(-0.1 * art.K[0, 0])
        assert server.retrieve_param_float("MC_ROLLRATE_D") == np.float32(-0.01 * art.K[0, 1])
        assert server.retrieve_param_int("MC_ROLL_LIM") == round(10.0 * art.u_max[0])  # bytewise, like MAVSDK
        assert server.retrieve_param_float("MC_RATE_DT") == np.float32(art.Ts)
        assert server.retrieve_param_float("MC_OTHER") == 1.0

        res = run_cli(
            "mavlink", "upload", pend, "--connect", f"udpout:127.0.0.1:{port}", "--mapping", mapping, "--dry-run"
        )
        assert res.code == 0 and "dry run: 0 parameter(s) would change, 4 already match" in res.out

        mapping.write_text('[[param]]\ngain = "K[0,0]"\nname = "MC_MISSING"\n')
        argv = ("mavlink", "upload", pend, "--connect", f"udpout:127.0.0.1:{port}", "--mapping", mapping)
        assert_refused((*argv, "--retries", "2"), "vehicle lacks 1 parameter(s): MC_MISSING", mapping.parent)
    finally:
        sdk.destroy()
        cfg.destroy()


def test_a_vehicle_whose_gl_hash_is_real32_is_refused_in_one_line_before_any_write(pend, retuned):
    """Every parameter's type is checked against the vehicle's, GL_HASH included, before the first PARAM_SET: one
    stderr line (none of the uploader's INFO chatter before it), exit 2, every gain still the old one."""
    old, new = load(pend), load(retuned)
    port = udp_port()
    served = as_served(firmware_params(old), GL_HASH=REAL32)
    with mavsdk_vehicle(f"udpin://127.0.0.1:{port}", served) as server:
        argv = (GAINLINK, "mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--retries", "2")
        res = assert_refused(argv, "GL_HASH is REAL32 on the vehicle, INT32 in the plan; nothing was changed",
                             retuned.parent, process=True)  # fmt: skip
        assert "vehicle 1/1 (MAV_AUTOPILOT_GENERIC, not a gainlink node)" in res.err
        for name in changed_gains(old, new):
            assert server.retrieve_param_float(name) == served[name][1], name


def test_a_third_party_vehicle_with_the_gainlink_names_is_never_said_to_run_the_set(pend, retuned):
    """MAVSDK serving every GL_* parameter with the right types only stores what it is sent: the uploader may say
    that it holds the values and GL_HASH (each echo verified), never that a gain set was committed."""
    old, new = load(pend), load(retuned)
    port = udp_port()
    with mavsdk_vehicle(f"udpin://127.0.0.1:{port}", as_served(firmware_params(old))) as server:
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}")
        assert res.code == 0, res.err
        assert "gain set committed" not in res.out
        assert "GL_HASH echoed, commit NOT confirmed (the vehicle does not identify as a gainlink node" in res.out
        assert "vehicle 1/1 (MAV_AUTOPILOT_GENERIC, not a gainlink node)" in res.out
        # what it does claim is true: the vehicle holds every new value and the new hash
        for name, value in changed_gains(old, new).items():
            assert server.retrieve_param_float(name) == value, name
        assert server.retrieve_param_int("GL_HASH") == as_int32(gain_set(new).crc32)


def test_target_system_chooses_among_two_vehicles_and_the_choice_is_named(mavlink_exe, pend, retuned):
    """Two vehicles send to the uploader's port: gainlink's host app (1/1) and a MAVSDK vehicle (7/1). The target
    options pick one and the summary names it; the other is never written to. An absent target is one line."""
    new = load(retuned)
    port = udp_port()
    fw = MavlinkFirmware(mavlink_exe, url=f"udpout:127.0.0.1:{port}").start()
    try:
        with mavsdk_vehicle(f"udpout://127.0.0.1:{port}", {"MC_ROLLRATE_P": (REAL32, 0.15)}, system_id=7) as server:
            url = f"udpin:127.0.0.1:{port}"
            res = run_cli("mavlink", "upload", retuned, "--connect", url, "--target-system", "1")
            assert res.code == 0, res.err
            assert "to vehicle 1/1 (MAV_AUTOPILOT_GENERIC, a gainlink node)" in res.out
            assert "gain set committed" in res.out
            assert server.retrieve_param_float("MC_ROLLRATE_P") == np.float32(0.15)

            argv = ("mavlink", "upload", pend, "--connect", url, "--target-system", "7", "--retries", "1")
            res = assert_refused(argv, "vehicle 7/1 (MAV_AUTOPILOT_GENERIC, not a gainlink node)", pend.parent)
            assert "is not gainlink firmware" in res.err

            argv = (GAINLINK, "mavlink", "upload", pend, "--connect", url, "--target-system", "9",
                    "--heartbeat-timeout", "1.5")  # fmt: skip
            res = assert_refused(argv, "no heartbeat from vehicle 9/* on", pend.parent, process=True)
            assert "1/1" in res.err and "7/1" in res.err
    finally:
        fw.stop()
    assert f"committed gain set crc32 0x{gain_set(new).crc32:08x}" in fw.stderr_text()
