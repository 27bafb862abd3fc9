"""MAVLink faults against the real firmware app: a lossy link, a refused parameter midway (rollback),
a refused persist (rollback of a committed set), no heartbeat, non-finite values and invalid commits."""

from __future__ import annotations

import math

import numpy as np
from gainlink.mavlink.link import MavLink
from gainlink.mavlink.params import INT32, REAL32, Encoding, as_int32
from gainlink.mavlink.relay import LossyUdpRelay
from gainlink.mavlink.session import ParamSession
from gainlink.shipping.artifact import load
from gainlink.shipping.codegen import gain_set, payload_crc32
from support.cli import assert_refused, run_cli
from support.mavlink import closed_loop, read_params, reference_u, start_firmware
from support.race import ResetAfterCommit


def values_of(port: int) -> dict:
    return {n: p.value for n, p in read_params(port).items()}


def test_upload_through_a_lossy_link_completes_and_verifies(mavlink_exe, pend, retuned, tmp_path):
    fw, port = start_firmware(mavlink_exe, tmp_path / "params.txt")
    try:
        with LossyUdpRelay(upstream=("127.0.0.1", port), drop=0.2, duplicate=0.1, reorder=0.1, seed=7) as relay:
            res = run_cli(
                "mavlink",
                "upload",
                retuned,
                "--connect",
                relay.url,
                "--persist",
                "--timeout",
                "0.05",
                "--retries",
                "30",
            )
            assert res.code == 0, res.err
            assert relay.stats.dropped > 0 and relay.stats.duplicated > 0 and relay.stats.reordered > 0
        assert "persisted" in res.out
        retries = int(res.out.rsplit(" retries", 1)[0].rsplit(" ", 1)[1])
        assert retries > 0  # the losses were really worked around
        new = load(retuned)
        assert values_of(port)["GL_HASH"] & 0xFFFFFFFF == gain_set(new).crc32
        Y, R, U = closed_loop(port, new, steps=100)
        np.testing.assert_allclose(U, reference_u(new, Y, R), atol=1e-4)
    finally:
        fw.stop()


def test_a_parameter_refused_midway_rolls_back_every_change(mavlink_exe, pend, tmp_path):
    mapping = tmp_path / "map.toml"
    mapping.write_text(
        '[[param]]\ngain = "K[0,0]"\nname = "GL_K_0_0"\nscale = 1.5\n'
        '[[param]]\ngain = "K[0,1]"\nname = "GL_K_0_1"\nscale = 1.5\n'
        '[[param]]\ngain = "u_max[0]"\nname = "GL_DIM_N"\ntype = "INT32"\n'  # read-only: the vehicle refuses it
        '[[param]]\ngain = "K[0,2]"\nname = "GL_K_0_2"\nscale = 1.5\n'
        '[[param]]\ngain = "L[0,0]"\nname = "GL_L_0_0"\nscale = 0.5\n'
    )
    fw, port = start_firmware(mavlink_exe, None)
    try:
        before = values_of(port)
        res = run_cli(
            "mavlink",
            "upload",
            pend,
            "--connect",
            f"udpout:127.0.0.1:{port}",
            "--mapping",
            mapping,
            "--window",
            "1",
            "--retries",
            "2",
        )
        assert res.code == 3, (res.code, res.err)
        err = res.err
        assert "GL_DIM_N refused" in err and "read-only" in err
        assert "restored GL_K_0_0" in err and "restored GL_K_0_1" in err
        assert "GL_K_0_2" not in err and "GL_L_0_0" not in err  # never sent, so nothing to restore
        assert "every changed parameter was restored" in err
        after = values_of(port)
        assert after == before
    finally:
        fw.stop()


def test_a_refused_persist_rolls_back_the_committed_set(mavlink_exe, pend, retuned):
    fw, port = start_firmware(mavlink_exe, None)  # no --storage: MAV_CMD_PREFLIGHT_STORAGE fails
    try:
        old = load(pend)
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--persist")
        assert res.code == 3, res.err
        assert "persist refused: COMMAND_ACK result MAV_RESULT_FAILED" in res.err
        assert "re-committed the previous gain set" in res.err
        values = values_of(port)
        assert values["GL_HASH"] & 0xFFFFFFFF == gain_set(old).crc32
        assert values["GL_K_0_0"] == float(np.float32(old.K[0, 0]))
        Y, R, U = closed_loop(port, old, steps=100)
        np.testing.assert_allclose(U, reference_u(old, Y, R), atol=1e-4)
    finally:
        fw.stop()


def _heartbeats(sock) -> int:
    """The ground station's HEARTBEATs waiting on the bound UDP socket ``sock``."""
    from pymavlink.dialects.v20 import common as mavlink2

    parser, count = mavlink2.MAVLink(None), 0
    sock.setblocking(False)
    while True:
        try:
            data = sock.recv(4096)
        except BlockingIOError:
            return count
        for m in parser.parse_buffer(bytearray(data)) or []:
            count += m.get_type() == "HEARTBEAT" and m.type == mavlink2.MAV_TYPE_GCS


def test_no_heartbeat_is_a_clear_error_within_the_timeout(tmp_path, pend):
    """The upload gives up after its own --heartbeat-timeout: while it waits it sends a HEARTBEAT every 0.5 s (a
    vehicle on a udpin port learns its address from it), and the silent port got at most two, where the default
    5 s would send ten."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # a bound port where nobody answers
        silent.bind(("127.0.0.1", 0))
        port = silent.getsockname()[1]
        argv = ("mavlink", "upload", pend, "--connect", f"udpout:127.0.0.1:{port}", "--heartbeat-timeout", "1")
        res = assert_refused(argv, "no heartbeat", tmp_path)
        beats = _heartbeats(silent)
    assert res.err == f"gainlink: error: no heartbeat on udpout:127.0.0.1:{port} within 1 s\n"
    assert 1 <= beats <= 2, beats


def test_non_finite_values_and_invalid_commits_are_refused_and_the_loop_keeps_its_set(mavlink_exe, pend):
    old = load(pend)
    crc_old = gain_set(old).crc32
    fw, port = start_firmware(mavlink_exe, None)
    try:
        with MavLink(f"udpout:127.0.0.1:{port}") as link:
            link.wait_heartbeat(timeout=5)
            s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE, retries=1)
            out = s.set([("GL_K_0_0", REAL32, math.nan)])
            assert not out.ok and out.refused["GL_K_0_0"] == (float(np.float32(old.K[0, 0])), "value out of range")
            out = s.set([("GL_K_0_0", REAL32, math.inf)])
            assert "GL_K_0_0" in out.refused
            # a commit whose hash is not the staged set's is refused
            out = s.set([("GL_HASH", INT32, as_int32(crc_old ^ 1))])
            assert out.refused["GL_HASH"][0] & 0xFFFFFFFF == crc_old
            # a staged set with u_min > u_max is refused even with its exact CRC: the library's range check
            gs = gain_set(old)
            fields = {k: v.copy() for k, v in gs.fields.items()}
            fields["u_min"][0] = np.float32(30.0)
            bad_crc = payload_crc32(header=gs.header, fields=fields)
            assert s.set([("GL_UMIN_0", REAL32, 30.0)]).ok  # staging alone is accepted
            out = s.set([("GL_HASH", INT32, as_int32(bad_crc))])
            assert out.refused["GL_HASH"][0] & 0xFFFFFFFF == crc_old
            # unknown and read-only parameters
            assert s.read(["GL_NOPE"])[1] == {"GL_NOPE": "does not exist"}
            out = s.set([("GL_DIM_N", INT32, 5)])
            assert out.refused["GL_DIM_N"] == (old.n, "read-only")
            assert s.set([("GL_UMIN_0", REAL32, float(old.u_min[0]))]).ok
        assert "commit refused" in fw.stderr_text()
        Y, R, U = closed_loop(port, old, steps=100)  # still the old set, bit for bit the reference
        np.testing.assert_allclose(U, reference_u(old, Y, R), atol=1e-4)
    finally:
        fw.stop()


def test_a_commit_the_node_does_not_run_is_not_confirmed_and_is_rolled_back(mavlink_exe, pend, retuned):
    """Another ground station resets the node to its compiled set right after the commit's echo: GL_HASH was
    echoed, but the node's AUTOPILOT_VERSION uid (the CRC-32 of the set it runs) is the old set's. The upload
    must not say "committed": it fails, restores every parameter, and the loop runs the old gains."""
    old, new = load(pend), load(retuned)
    fw, port = start_firmware(mavlink_exe, None)
    try:
        with ResetAfterCommit(node_port=port, crc=gain_set(new).crc32) as race:
            res = run_cli("mavlink", "upload", retuned, "--connect", race.url)
        assert race.reset_result == 0  # MAV_RESULT_ACCEPTED: the race really happened
        assert res.code == 3, (res.code, res.out, res.err)
        assert "gain set committed" not in res.out
        want = f"uid says it runs 0x{gain_set(old).crc32:x}, not crc32 0x{gain_set(new).crc32:08x}"
        assert "commit not confirmed" in res.err and want in res.err, res.err
        assert "every changed parameter was restored" in res.err
        after = values_of(port)
        assert after["GL_HASH"] & 0xFFFFFFFF == gain_set(old).crc32
        assert after["GL_K_0_0"] == np.float32(old.K[0, 0])
        Y, R, U = closed_loop(port, old, steps=100)
        np.testing.assert_allclose(U, reference_u(old, Y, R), atol=1e-4)
    finally:
        fw.stop()
