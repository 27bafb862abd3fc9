"""The CAN layout: DBC from the artifact, the fast codec against cantools, the firmware app against both.

The firmware's gainlink_can is exercised as a real process over python-can udp_multicast: samples go
out through the Python transport, commands come back and are compared with the float64 reference
law (float32 on the wire and in the C loop: relative tolerance 1e-4 of the command scale), in both
encodings (int16: the law is fed the quantised sample, and the command may be off by half a step).
The int16 encoding's own tests are in test_can_scaled.py.
"""

from __future__ import annotations

import gc
import math
import struct

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
from support.net import udp_port


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


#: Wire format 4 as docs/design.md writes it (written out here, never read from gainlink.shipping.flags): per header
#: ``(bytes, status bits carried, saturation bits a frame)``. Classic: byte 2 the flags' bits 0-7, byte 3's low nibble
#: the frame's saturation bits and its high nibble the flags' bits 8-11. CAN FD: bytes 2-3 the flags (uint16 LE),
#: bytes 4-7 the saturation bits (uint32 LE).
HEADERS = {False: (4, 0x0FFF, 4), True: (8, 0xFFFF, 32)}


def _documented_header(fd: bool, seq: int, status: int, sat: int) -> bytes:
    """A header's bytes at the positions docs/design.md gives them (status bits beyond the header dropped)."""
    _, carried, _ = HEADERS[fd]
    status &= carried
    if fd:
        return struct.pack("<HHI", seq, status, sat)
    return struct.pack("<HBB", seq, status & 0xFF, sat | (status >> 8) << 4)


def _wide_artifact():
    """A real design with a wide sample: the quadrotor's lateral channel seen by four redundant sensors per state
    (16 outputs) with integral action on one of them (1 reference): 17 values a sample, 1 input."""
    import tomllib

    from gainlink.shipping.artifact import from_dict
    from support.designs import designed
    from support.paths import EXAMPLES

    spec = tomllib.loads((EXAMPLES / "quadrotor_lateral.toml").read_text())
    states = spec["plant"]["states"]
    spec["plant"]["outputs"] = [f"{s}_{k}" for k in "abcd" for s in states]
    spec["plant"]["C"] = [[1.0 if j == i % 4 else 0.0 for j in range(4)] for i in range(16)]
    spec["integral"]["outputs"] = ["y_a"]
    spec["observer"]["V_diag"] = spec["observer"]["V_diag"][:1] * 16
    for k in ("y_min", "y_max", "r_min", "r_max"):
        del spec["limits"][k]
    spec["units"] = {}
    return from_dict(designed(spec))


@pytest.mark.parametrize("encoding", ["float32", "int16"])
def test_a_wide_sample_takes_two_fd_frames_and_cantools_decodes_every_one(encoding):
    """Wire format 4: an FD frame's 8-byte header leaves 56 bytes for 14 float32 (or 28 int16) values, so the
    17 values of a 16-output sample take 2 FD frames (float32: 64 and 20 bytes) or 1 (int16: 42 bytes, sent as 48),
    where format 3's 4 values a frame took 5; classic frames are as before (1 float32 or 2 int16 values each).
    cantools decodes every frame of the layout's DBC to the values the link's codec sent."""
    from gainlink.shipping.can_layout import FD_LENGTHS

    art = _wide_artifact()
    k, width = art.p + art.q, {"float32": 4, "int16": 2}[encoding]
    assert (art.p, art.q, k) == (16, 1, 17)
    names = [*art.signals["outputs"], *art.signals["references"]]
    ranges = {n: [-5.0, 5.0] for n in names} if encoding == "int16" else None
    fd = CanTransport({"interface": "virtual", "fd": True, "encoding": encoding, "ranges": ranges}, artifact=art)
    classic = CanTransport({"interface": "virtual", "encoding": encoding, "ranges": ranges}, artifact=art)
    per_fd = (64 - 8) // width
    chunks = [min(per_fd, k - i) for i in range(0, k, per_fd)]
    assert len(fd.layout.measurement) == math.ceil(k / per_fd) == {"float32": 2, "int16": 1}[encoding]
    lengths = [min(n for n in FD_LENGTHS if n >= 8 + width * c) for c in chunks]
    assert [s.length for s in fd.layout.measurement] == lengths
    assert len(classic.layout.measurement) == math.ceil(k / (4 // width))
    db = cantools.database.load_string(fd.layout.dbc(), database_format="dbc")
    rng = np.random.default_rng(5)
    for seq in range(20):
        v = rng.uniform(-4.0, 4.0, k)
        frames = fd.encode_sample(seq=seq, y=v[: art.p], r=v[art.p :])
        assert len(frames) == len(chunks) and all(f.is_fd for f in frames)
        sent = v.astype(np.float32) if encoding == "float32" else np.round(v / (10.0 / 65534)) * (10.0 / 65534)
        for frame, spec in zip(frames, fd.layout.measurement):
            assert bytes(frame.data[:8]) == _documented_header(True, seq, 0, 0)
            msg = db.get_message_by_frame_id(frame.arbitration_id)
            assert msg.is_fd and msg.length == len(frame.data)
            d = msg.decode(bytes(frame.data), decode_choices=False)
            assert (d["seq"], d["status"], d["status_hi"], d["sat"]) == (seq, 0, 0, 0)
            got = np.array([d[n] for n in spec.signals])
            want = sent[spec.first : spec.first + len(spec.signals)]
            np.testing.assert_allclose(got, want, rtol=0, atol=0 if encoding == "float32" else 1e-12)


def _patterns(n: int, rng) -> list[int]:
    """Saturation masks of an ``n``-value vector: none, each bit alone, all, and a few at random."""
    return [0, (1 << n) - 1, *(1 << i for i in range(n)), *(int(x) for x in rng.integers(0, 1 << n, 6))]


@pytest.mark.parametrize("fd", [False, True])
def test_every_flag_and_saturation_bit_round_trips_through_c_python_and_cantools(pend, fd):
    """Every status bit (each alone, CAPPED with others, all 16) times every saturation bit of a 17-value vector
    (each alone, none, all, random masks): the link's Python codec, the host CAN node's C codec (gl_can_layout.c
    through ctypes) and cantools reading the generated DBC make and read the same frames, whose headers are the bytes
    docs/design.md gives (classic: the flags' bits 12-15 do not travel). The MPC's DBC names CAPPED in
    ``status_hi``'s value table."""
    import ctypes

    from gainlink.hil.links.can import Assembler, FrameCodec
    from gainlink.laws import design
    from gainlink.shipping.artifact import from_dict
    from gainlink.spec import load_spec
    from support.can_codec import c_codec
    from support.paths import EXAMPLES

    mpc = from_dict(design(load_spec(EXAMPLES / "quadrotor_hover_mpc.toml")).artifact)
    hi = cantools.database.load_string(layout_for(mpc, fd=fd).dbc(), database_format="dbc")
    hi = hi.get_message_by_name("Command0").get_signal_by_name("status_hi")
    assert {int(k): str(v) for k, v in hi.choices.items()} == {1: "CAPPED"}

    layout = layout_for(_wide_artifact(), fd=fd, base_id=0x200)
    specs, (size, carried, sat_bits) = layout.measurement, HEADERS[fd]
    db = cantools.database.load_string(layout.dbc(), database_format="dbc")
    codec, rx = FrameCodec(specs, fd=fd), Assembler(FrameCodec(specs, fd=fd))
    lib, _Scale, Layout, Frame = c_codec(load(pend))
    c_layout = Layout()
    lib.gl_can_layout_init(ctypes.byref(c_layout), 0x200, int(fd), 0)
    assert c_layout.per_frame == layout.per_frame == min(sat_bits, ((64 if fd else 8) - size) // 4)
    rng = np.random.default_rng(2)
    values = rng.normal(size=codec.size).astype(np.float32)
    c_values = (ctypes.c_float * codec.size)(*values)
    statuses = [0, *(1 << b for b in range(16)), 0x100 | 0x81, 0x0FFF, 0xFFFF]
    for seq, (status, sat) in enumerate((st, m) for st in statuses for m in _patterns(codec.size, rng)):
        mask = np.array([(sat >> i) & 1 for i in range(codec.size)], dtype=bool)
        frames = codec.encode(seq=seq, values=values, status=status, sat=mask)
        got = [rx.feed(f) for f in frames][-1]
        assert got is not None and got[2] == status & carried and np.array_equal(got[3], mask)
        for j, (frame, spec) in enumerate(zip(frames, specs)):
            n = len(spec.signals)
            bits = (sat >> spec.first) & ((1 << n) - 1)
            data = bytes(frame.data)
            assert data[:size] == _documented_header(fd, seq, status, bits), (status, sat, j)
            d = db.get_message_by_frame_id(frame.arbitration_id).decode(data, decode_choices=False)
            assert (d["seq"], d["status"] | d["status_hi"] << 8, d["sat"]) == (seq, status & carried, bits)
            c_frame = Frame()
            lib.gl_can_layout_encode(ctypes.byref(c_layout), frame.arbitration_id, j, seq, status, sat, c_values,
                                     None, codec.size, ctypes.byref(c_frame))  # fmt: skip
            assert bytes(c_frame.data[: c_frame.len]) == data, (status, sat, j)
            c_seq, c_status, c_sat = ctypes.c_uint16(), ctypes.c_uint16(), ctypes.c_uint32()
            lib.gl_can_layout_header(ctypes.byref(c_layout), ctypes.byref(c_frame), ctypes.byref(c_seq),
                                     ctypes.byref(c_status), ctypes.byref(c_sat))  # fmt: skip
            assert (c_seq.value, c_status.value, c_sat.value) == (seq, status & carried, bits)


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


@pytest.mark.parametrize("encoding", ["float32", "int16"])
def test_the_firmware_node_answers_a_wide_sample_sent_in_fd_frames(encoding):
    """The host CAN node (gainlink_can, a real process on udp_multicast) of the 16-output design assembles each
    sample from its FD frames (float32: 2 frames of 14 and 3 values; int16: 1 of 17) and answers it with the law's
    command: the float64 reference law on what the node decoded (float32 on the wire; int16 quantised), within float32
    rounding (and half an int16 step of the command), the saturation bits equal."""
    from gainlink.hil.links.can_firmware import firmware_can_executable

    art = _wide_artifact()
    names = [*art.signals["outputs"], *art.signals["references"]]
    ranges = {n: [-5.0, 5.0] for n in names}
    transport = CanTransport({**udp_transport(fd=True), "encoding": encoding, "ranges": ranges}, artifact=art)
    assert transport.describe()["frames_per_sample"] == {"float32": 2, "int16": 1}[encoding]
    peer = ControllerProcess([str(firmware_can_executable(art)), *transport.controller_argv()])
    half_step_u = 0.0 if encoding == "float32" else transport.layout.command[0].factors[0] / 2
    transport.open()
    try:
        peer.start()
        peer.check_artifact(art.sha256)
        rng = np.random.default_rng(3)
        Y = rng.normal(scale=0.05, size=(60, art.p))
        R = rng.normal(scale=0.5, size=(60, art.q))
        Y[20:23] *= 40.0  # far off: the torque saturates for a few steps
        cmds = _exchange(art, transport, [(k, Y[k], R[k]) for k in range(60)])
        assert all(c is not None for c in cmds)
        seen = [transport.received_sample(y=Y[k], r=R[k]) for k in range(60)]
        ref = ReferenceLoop(art).run(np.array([s[0] for s in seen]), np.array([s[1] for s in seen]))
        scale = float(np.abs(ref.u).max())
        np.testing.assert_allclose(np.array([c.u for c in cmds]), ref.u, rtol=0, atol=1e-4 * scale + half_step_u)
        assert np.array_equal(np.array([c.saturated for c in cmds]), ref.saturated) and ref.saturated.any()
    finally:
        peer.close()
        transport.close()


@pytest.mark.parametrize("reply, hit", [(False, "bus"), (True, "send bus"), (True, "receive bus")])
def test_a_ctrl_c_at_the_start_of_a_buss_shutdown_still_shuts_every_bus_and_is_raised(pend, reply, hit, caplog):
    """A Ctrl-C that lands as python-can's ``shutdown`` of one of the link's buses starts (before it marks the bus
    shut) is raised after every bus of the link is shut: none is left to its finaliser, which logged "was not
    properly shut down" above an interrupted command's one line (seen once on a HIL run interrupted as it closed)."""
    config = udp_transport(fd=False)
    if reply:
        config["reply_port"] = udp_port()
    transport = CanTransport(config, artifact=load(pend))
    transport.open()
    buses = list(dict.fromkeys([transport.bus, transport._tx]))
    assert len(buses) == (2 if reply else 1)
    bus = transport._tx if hit == "send bus" else transport.bus
    calls = []

    def interrupted_once(target=bus):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt  # as a signal handled at the call's first instruction
        type(target).shutdown(target)

    bus.shutdown = interrupted_once
    with pytest.raises(KeyboardInterrupt):
        transport.close()
    assert len(calls) == 2 and transport.bus is None and transport._tx is None
    assert all(b._is_shutdown and b._multicast._socket.fileno() == -1 for b in buses)
    with caplog.at_level("WARNING", logger="can"):
        del bus, buses, interrupted_once
        gc.collect()
    assert "not properly shut down" not in caplog.text
