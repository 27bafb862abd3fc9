"""The CAN layout: DBC from the artifact, the fast codec against cantools, the firmware app against both.

The firmware's gainlink_can is exercised as a real process over python-can udp_multicast: samples go
out through the Python transport, commands come back and are compared with the float64 reference
law (float32 on the wire and in the C loop: relative tolerance 1e-4 of the command scale), in both
encodings (int16: the law is fed the quantised sample, and the command may be off by half a step).
The int16 encoding's own tests are in test_can_scaled.py.
"""

from __future__ import annotations

import math

import cantools
import numpy as np
import pytest
from gainlink.errors import TransportError
from gainlink.hil.links.base import STATUS_FAULT
from gainlink.hil.links.can import CanTransport, firmware_can_argv
from gainlink.hil.loop.controller import ControllerProcess
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping.artifact import load
from gainlink.shipping.can_layout import layout_for
from support.cli import run_cli
from support.hil import PENDULUM_RANGES, udp_transport


@pytest.mark.parametrize("fd", [False, True])
def test_dbc_round_trips_through_cantools_and_matches_the_fast_codec(pend, fd):
    art = load(pend)
    layout = layout_for(art, fd=fd, base_id=0x200)
    db = cantools.database.load_string(layout.dbc(), database_format="dbc")
    # Classic CAN carries one value per frame: p + q = 3 measurement frames; FD packs them in one.
    assert len(layout.measurement) == (1 if fd else art.p + art.q)
    assert len(layout.command) == 1
    assert {m.frame_id for m in db.messages} == {0x200 + 0x10 + i for i in range(len(layout.measurement))} | {0x200}
    names = [s for spec in layout.measurement for s in spec.signals]
    assert names == ["y_x", "y_theta", "r_x"]
    transport = CanTransport({"interface": "virtual", "fd": fd, "base_id": 0x200}, artifact=art)
    rng = np.random.default_rng(1)
    for _ in range(20):
        y, r = rng.normal(size=art.p), rng.normal(size=art.q)
        seq = int(rng.integers(0, 65536))
        frames = transport.encode_sample(seq=seq, y=y, r=r)
        values = dict(zip(names, np.concatenate([y, r]).astype(np.float32)))
        for frame, spec in zip(frames, layout.measurement):
            msg = db.get_message_by_frame_id(frame.arbitration_id)
            assert msg.is_fd == fd and msg.length == len(frame.data)
            decoded = msg.decode(bytes(frame.data))
            assert (
                decoded["seq"] == seq and decoded["status"] == 0 and decoded["sat"] == 0 and decoded["status_hi"] == 0
            )
            for name in spec.signals:
                assert decoded[name] == pytest.approx(float(values[name]), rel=0, abs=0)
            want = {"seq": seq, "status": 0, "sat": 0, "status_hi": 0, **{n: float(values[n]) for n in spec.signals}}
            assert msg.encode(want) == bytes(frame.data)


@pytest.mark.parametrize("fd", [False, True])
def test_a_command_frame_carries_every_flag_bit_as_the_dbc_says(fd):
    """Wire format 3: a command's flags 0-7 in ``status``, 8-11 in ``status_hi`` (an MPC's CAPPED, 0x100, is its bit
    0), the frame's saturation bits in ``sat``; cantools reading the generated DBC and the link's codec agree on every
    combination, and the MPC's DBC names CAPPED in ``status_hi``'s value table."""
    from gainlink.hil.links.can import Assembler, FrameCodec
    from gainlink.laws import design
    from gainlink.shipping.artifact import from_dict
    from gainlink.spec import load_spec
    from support.paths import EXAMPLES

    art = from_dict(design(load_spec(EXAMPLES / "quadrotor_hover_mpc.toml")).artifact)
    layout = layout_for(art, fd=fd, base_id=0x200)
    db = cantools.database.load_string(layout.dbc(), database_format="dbc")
    assert all(len(spec.signals) <= 4 for spec in layout.command), "a frame carries at most 4 values"
    hi = db.get_message_by_name(layout.command[0].name).get_signal_by_name("status_hi")
    assert {int(k): str(v) for k, v in hi.choices.items()} == {1: "CAPPED"}
    codec = FrameCodec(layout.command, fd=fd)
    u = np.array([0.5, -1.0, 2.0, 3.5], dtype=np.float32)
    for status in (0x000, 0x001, 0x080, 0x100, 0x181, 0xFFF):
        for sat in (np.zeros(4, bool), np.array([True, False, True, True])):
            frames = codec.encode(seq=7, values=u, status=status, sat=sat)
            rx = Assembler(codec)
            got = [rx.feed(f) for f in frames][-1]
            assert got is not None and got[2] == status and np.array_equal(got[3], sat)
            for frame, spec in zip(frames, layout.command):
                d = db.get_message_by_frame_id(frame.arbitration_id).decode(bytes(frame.data), decode_choices=False)
                assert d["status"] | d["status_hi"] << 8 == status
                assert d["sat"] == sum(int(sat[spec.first + i]) << i for i in range(len(spec.signals)))


def test_dbc_command_writes_a_file(pend, tmp_path):
    out = tmp_path / "pendulum.dbc"
    res = run_cli("hil", "dbc", pend, "--fd", "--out", out)
    assert res.code == 0, res.err
    db = cantools.database.load_file(out)
    assert sorted(m.name for m in db.messages) == ["Command0", "Measurement0"]


def _exchange(art, transport, samples):
    """Send each (seq, y, r) and collect the command answering it (None if it never comes)."""
    out = []
    for seq, y, r in samples:
        transport.send_frames(transport.encode_sample(seq=seq, y=y, r=r))
        cmd = None
        while True:
            c = transport.receive_command(timeout=2.0)
            if c is None or c.seq == seq:
                cmd = c
                break
        out.append(cmd)
    return out


@pytest.mark.parametrize("encoding", ["float32", "int16"])
@pytest.mark.parametrize("fd", [False, True])
def test_firmware_can_app_runs_the_law_over_udp_multicast(pend, can_firmware, fd, encoding):
    art = load(pend)
    transport = CanTransport({**udp_transport(fd=fd), "encoding": encoding, "ranges": PENDULUM_RANGES}, artifact=art)
    peer = ControllerProcess([str(can_firmware), *transport.controller_argv()])
    # int16: the command arrives quantised, within half a step of the controller's float32 u.
    half_step_u = 0.0 if encoding == "float32" else transport.layout.command[0].factors[0] / 2
    transport.open()
    try:
        peer.start()
        peer.check_artifact(art.sha256)
        assert f"encoding={encoding}" in peer.ready_line
        rng = np.random.default_rng(7)
        Y = rng.normal(scale=[0.2, 0.05], size=(200, art.p)).astype(np.float32)
        R = rng.normal(scale=0.5, size=(200, art.q)).astype(np.float32)
        Y[50:53] *= 400.0  # drive the command into its limits for a few steps (int16: theta also beyond its range)
        cmds = _exchange(art, transport, [(k, Y[k], R[k]) for k in range(200)])
        # The law sees what the controller decoded: float32, and with int16 the quantised, range-clipped sample.
        seen = [transport.received_sample(y=Y[k], r=R[k]) for k in range(200)]
        Ys, Rs = np.array([s[0] for s in seen]), np.array([s[1] for s in seen])
        ref = ReferenceLoop(art).run(Ys, Rs)
        assert all(c is not None for c in cmds)
        U = np.array([c.u for c in cmds])
        scale = float(np.abs(ref.u).max())
        np.testing.assert_allclose(U, ref.u, rtol=0, atol=1e-4 * scale + half_step_u)
        assert np.array_equal(np.array([c.saturated for c in cmds]), ref.saturated)
        assert ref.saturated.any()
        if encoding == "int16":  # samples 50..52 go beyond the (symmetric) ranges: sent saturated, and counted
            y_hi = np.array([PENDULUM_RANGES[n][1] for n in art.signals["outputs"]])
            r_hi = np.array([PENDULUM_RANGES[n][1] for n in art.signals["references"]])
            beyond = int((np.abs(Y) > y_hi).sum() + (np.abs(R) > r_hi).sum())
            assert beyond > 0 and transport.describe()["encoding_clipped"] == beyond
        # A non-finite sample (int16: raw -32768): safe command (zero clamped), fault bit, state untouched.
        nan_cmd = _exchange(art, transport, [(200, np.array([math.nan, 0.0]), np.zeros(art.q))])[0]
        assert nan_cmd.status & STATUS_FAULT and np.all(np.abs(nan_cmd.u) <= half_step_u)
        # A duplicate of an answered sample is ignored; the next sample continues the sequence.
        transport.send_frames(transport.encode_sample(seq=199, y=Y[199], r=R[199]))
        assert transport.receive_command(timeout=0.3) is None
        nxt = _exchange(art, transport, [(201, Y[0], R[0])])[0]
        loop = ReferenceLoop(art)
        loop.run(Ys, Rs)
        want = loop.step(Ys[0], Rs[0]).u
        np.testing.assert_allclose(nxt.u, want, rtol=0, atol=1e-4 * scale + half_step_u)
    finally:
        peer.close()
        transport.close()


def test_firmware_argv_refuses_interfaces_the_app_cannot_speak(pend):
    art = load(pend)
    with pytest.raises(TransportError, match="firmware CAN app speaks"):
        firmware_can_argv({"interface": "virtual"}, layout=layout_for(art))


def test_bus_that_cannot_open_is_one_clear_error(pend):
    transport = CanTransport({"interface": "socketcan", "channel": "gl_no_such_can0"}, artifact=load(pend))
    with pytest.raises(TransportError, match=r"cannot open CAN bus \(interface=socketcan, channel=gl_no_such_can0\)"):
        transport.open()


def test_udp_multicast_without_a_route_says_how_to_add_one(pend):
    # A loopback-only network namespace (a real kernel one: unshare -n, as root like CI) has no multicast route.
    import shutil
    import subprocess
    import sys

    assert shutil.which("unshare"), "util-linux unshare (Debian's base system) is needed for a loopback-only namespace"
    code = (
        "import sys, numpy as np\n"
        "from gainlink.shipping.artifact import load\n"
        "from gainlink.errors import TransportError\n"
        "from gainlink.hil.links.can import CanTransport\n"
        "t = CanTransport({'interface': 'udp_multicast', 'channel': '239.74.1.1', 'port': 45678, 'hop_limit': 0},"
        " artifact=load(sys.argv[1]))\n"
        "try:\n"
        "    t.open(); t.send_frames(t.encode_sample(seq=0, y=np.zeros(2), r=np.zeros(1))); print('sent')\n"
        "except TransportError as e:\n"
        "    print(e)\n"
        "finally:\n"
        "    t.close()\n"
    )
    bare = subprocess.run(
        [
            "unshare",
            "-n",
            "sh",
            "-c",
            'ip link set lo up; exec "$0" -c "$1" "$2"',
            sys.executable,
            code,
            str(pend),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "ip route add 224.0.0.0/4 dev lo" in bare.stdout, bare.stdout + bare.stderr
    routed = subprocess.run(
        [
            "unshare",
            "-n",
            "sh",
            "-c",
            'ip link set lo up multicast on && ip route add 224.0.0.0/4 dev lo && exec "$0" -c "$1" "$2"',
            sys.executable,
            code,
            str(pend),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert routed.stdout.strip() == "sent", routed.stdout + routed.stderr
