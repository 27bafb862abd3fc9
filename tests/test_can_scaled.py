"""Scaled-integer CAN signals (transport ``encoding = "int16"``): the DBC, the fast codec, the C codec, a closed loop.

Each value is a signed 16-bit raw value, ``physical = raw * factor + offset`` with ``factor = (max - min) /
65534`` and ``offset = (max + min) / 2`` from its range; raw -32768 is reserved for "not a number". The
bounds below are computed from the ranges, never copied.
"""

from __future__ import annotations

import ctypes
import dataclasses
import json
import logging
import math
import struct

import cantools
import numpy as np
import pytest
from gainlink.errors import TransportError
from gainlink.hil.links.can import Assembler, CanTransport, FrameCodec, firmware_can_argv
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.shipping.artifact import load
from gainlink.shipping.can_layout import FD_LENGTHS, INT16_MAX, INT16_NAN, dequantise, quantise
from support.can_codec import c_codec
from support.cli import assert_refused, run_cli
from support.hil import PENDULUM_RANGES, pendulum_scenario, udp_transport, write_scenario

SPAN = 2 * INT16_MAX  # raw steps across a range


def _int16(art, *, fd: bool = False, ranges: dict | None = None) -> CanTransport:
    ranges = PENDULUM_RANGES if ranges is None else ranges
    cfg = {"interface": "virtual", "fd": fd, "encoding": "int16", "ranges": ranges}
    return CanTransport(cfg, artifact=art)


def _value_ranges(art, ranges: dict) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Artifact names, minima and maxima of the sample (y then r) as the user gave them."""
    names = list(art.signals["outputs"]) + list(art.signals["references"])
    return names, np.array([ranges[n][0] for n in names]), np.array([ranges[n][1] for n in names])


@pytest.mark.parametrize("fd", [False, True])
def test_int16_dbc_describes_the_scaled_signals_and_matches_the_fast_codec(pend, fd):
    art = load(pend)
    transport = _int16(art, fd=fd)
    layout = transport.layout
    names, lo, hi = _value_ranges(art, PENDULUM_RANGES)
    k = len(names)
    if fd:  # one frame: 8 header bytes (wire format 4's FD header) + 2 per value, rounded up to a CAN FD length
        assert [s.length for s in layout.measurement] == [min(n for n in FD_LENGTHS if n >= 8 + 2 * k)]
    else:  # classic: two int16 values per 8-byte frame
        assert len(layout.measurement) == math.ceil(k / 2) and all(s.length == 8 for s in layout.measurement)
    db = cantools.database.load_string(layout.dbc(), database_format="dbc")
    dbc_names = [s for spec in layout.measurement for s in spec.signals]
    for dbc_name, a, b in zip(dbc_names, lo, hi):
        sig = db.get_message_by_name(
            next(s.name for s in layout.measurement if dbc_name in s.signals)
        ).get_signal_by_name(dbc_name)
        assert (sig.length, sig.is_signed, sig.is_float, sig.byte_order) == (16, True, False, "little_endian")
        assert (sig.scale, sig.offset, sig.minimum, sig.maximum) == ((b - a) / SPAN, (b + a) / 2, a, b)
        assert sig.choices[INT16_NAN] == "not_a_number"
    u_sig = db.get_message_by_frame_id(layout.command[0].arbitration_id).signals[4]
    assert (u_sig.minimum, u_sig.maximum) == (float(art.u_min[0]), float(art.u_max[0]))  # inputs: artifact limits

    rng = np.random.default_rng(3)
    samples = [rng.uniform(lo, hi) for _ in range(50)] + [lo.copy(), hi.copy(), (lo + hi) / 2]
    for i, v in enumerate(samples):
        frames = transport.encode_sample(seq=i, y=v[: art.p], r=v[art.p :])
        values = dict(zip(dbc_names, v))
        for frame, spec in zip(frames, layout.measurement):
            msg = db.get_message_by_frame_id(frame.arbitration_id)
            assert msg.is_fd == fd and msg.length == len(frame.data)
            want = {"seq": i, "status": 0, "sat": 0, "status_hi": 0, **{n: float(values[n]) for n in spec.signals}}
            assert msg.encode(want) == bytes(frame.data)  # cantools rounds like the codec (half to even)
            decoded = msg.decode(bytes(frame.data))
            for n, f in zip(spec.signals, spec.factors):
                assert abs(decoded[n] - values[n]) <= f / 2 * (1 + 1e-9), n
    assert transport.tx.clipped == 0

    # Commands (controller -> plant) through the codec the bridge decodes them with, against cantools.
    cmd = FrameCodec(layout.command, fd=fd)
    rx = Assembler(cmd)
    msg = db.get_message_by_frame_id(layout.command[0].arbitration_id)
    f_u = layout.command[0].factors[0]
    for i, u in enumerate(rng.uniform(art.u_min, art.u_max, size=(20, art.m))):
        (frame,) = cmd.encode(seq=i, values=u, sat=np.array([i % 2 == 0]))
        assert msg.encode({"seq": i, "status": 0, "sat": int(i % 2 == 0), "status_hi": 0, "u_F": float(u[0])}) == bytes(
            frame.data
        )
        seq, got, status, sat = rx.feed(frame)
        assert seq == i and status == 0 and sat[0] == (i % 2 == 0) and abs(got[0] - u[0]) <= f_u / 2 * (1 + 1e-9)


def test_int16_non_finite_values_travel_as_the_reserved_raw_value(pend):
    art = load(pend)
    transport = _int16(art, fd=True)
    (spec,) = transport.layout.measurement
    db = cantools.database.load_string(transport.layout.dbc(), database_format="dbc")
    (frame,) = transport.encode_sample(seq=5, y=np.array([math.nan, math.inf]), r=np.array([-math.inf]))
    raw = struct.unpack_from("<3h", frame.data, 8)  # after the FD header's 8 bytes
    assert raw == (INT16_NAN,) * 3 and transport.tx.clipped == 0
    decoded = db.decode_message(frame.arbitration_id, bytes(frame.data))  # any CAN tool names the reserved value
    assert [str(decoded[n]) for n in spec.signals] == ["not_a_number"] * 3
    rx = Assembler(FrameCodec(transport.layout.measurement, fd=True))
    _, values, _, _ = rx.feed(frame)
    assert np.isnan(values).all()


def test_int16_values_beyond_their_range_saturate_and_are_counted(pend, caplog):
    art = load(pend)
    transport = _int16(art)
    names, lo, hi = _value_ranges(art, PENDULUM_RANGES)
    rx = Assembler(FrameCodec(transport.layout.measurement, fd=False))
    with caplog.at_level(logging.WARNING, logger="gainlink.hil.links.can"):
        for seq, v in enumerate([hi * 3, lo * 3, hi + (hi - lo), (lo + hi) / 2]):
            done = None
            for frame in transport.encode_sample(seq=seq, y=v[: art.p], r=v[art.p :]):
                done = rx.feed(frame) or done
            want = np.clip(v, lo, hi)
            np.testing.assert_allclose(done[1], want, rtol=1e-12, atol=0)  # the range ends, raw +-32767
    assert transport.describe()["encoding_clipped"] == 3 * len(names)
    warnings = [r for r in caplog.records if "outside its range" in r.getMessage()]
    assert len(warnings) == 1  # warned once, counted always


def test_float32_stays_the_default_and_byte_identical(pend):
    art = load(pend)
    plain = CanTransport({"interface": "virtual"}, artifact=art)
    explicit = CanTransport({"interface": "virtual", "encoding": "float32", "ranges": PENDULUM_RANGES}, artifact=art)
    assert plain.layout == explicit.layout and plain.layout.dbc() == explicit.layout.dbc()
    y, r = np.array([0.125, -3.5e-3]), np.array([1e6])  # float32 has no range: 1e6 goes through
    for t in (plain, explicit):
        frames = t.encode_sample(seq=0x1234, y=y, r=r)
        assert [bytes(f.data) for f in frames] == [struct.pack("<HBBf", 0x1234, 0, 0, v) for v in (*y, *r)]
        assert "--encoding" not in firmware_can_argv({"interface": "udp_multicast"}, layout=t.layout)
    assert plain.describe()["encoding"] == "float32" and "encoding_clipped" not in plain.describe()


def test_missing_or_bad_ranges_are_one_line_errors(pend):
    art = load(pend)
    cases = {
        "no ranges": ({}, "needs a range for x, theta, r_x"),
        "one missing": ({"x": [-1, 1], "theta": [-1, 1]}, "needs a range for r_x:"),
        "unknown name": ({**PENDULUM_RANGES, "phi": [-1, 1]}, "ranges name no signal of the artifact: phi"),
        "empty range": ({**PENDULUM_RANGES, "theta": [1.0, 1.0]}, "ranges.theta must be [min, max]"),
        "reversed": ({**PENDULUM_RANGES, "x": [5, -5]}, "ranges.x must be [min, max]"),
        "not numbers": ({**PENDULUM_RANGES, "x": ["-5", 5]}, "ranges.x must be [min, max]"),
        "not a pair": ({**PENDULUM_RANGES, "x": 5}, "ranges.x must be [min, max]"),
    }
    for name, (ranges, needle) in cases.items():
        with pytest.raises(TransportError) as err:
            _int16(art, ranges=ranges)
        assert needle in str(err.value) and "\n" not in str(err.value), name
    with pytest.raises(TransportError, match="encoding must be float32 or int16, not 'int8'"):
        CanTransport({"interface": "virtual", "encoding": "int8"}, artifact=art)
    # An input without finite limits needs a range; a range given for an input overrides the limits.
    free = dataclasses.replace(art, u_min=np.array([-np.inf]), u_max=np.array([np.inf]))
    with pytest.raises(TransportError, match="needs a range for F:"):
        _int16(free)
    for a in (free, art):
        (spec,) = _int16(a, ranges={**PENDULUM_RANGES, "F": [-5.0, 15.0]}).layout.command
        assert spec.factors == (20.0 / SPAN,) and spec.offsets == (5.0,)


def test_cli_dbc_and_hil_run_with_int16(tmp_path, pend, cart_fmu):
    art = load(pend)
    cfg = {"interface": "udp_multicast", "encoding": "int16", "ranges": PENDULUM_RANGES}
    out = tmp_path / "int16.dbc"
    res = run_cli("hil", "dbc", pend, "--can", json.dumps(cfg), "--out", out)
    assert res.code == 0, res.err
    db = cantools.database.load_file(out)
    assert {
        s.length for m in db.messages for s in m.signals if s.name not in ("seq", "status", "sat", "status_hi")
    } == {16}
    assert db.get_message_by_name("Measurement0").get_signal_by_name("y_theta").maximum == PENDULUM_RANGES["theta"][1]
    bad = json.dumps({**cfg, "ranges": {"x": [-5, 5]}})
    assert_refused(("hil", "dbc", pend, "--can", bad), "needs a range for theta, r_x", tmp_path)
    # The same mistake in a scenario: one line, before any process starts.
    scenario = write_scenario(
        tmp_path / "s.toml",
        pendulum_scenario(
            gains=pend,
            fmu=cart_fmu,
            duration=0.5,
            transport={**udp_transport(fd=False), "encoding": "int16", "ranges": {"theta": [-1.0, 1.0]}},
        ),
    )
    argv = ("hil", "run", scenario, "--report", tmp_path / "report", "--no-progress")
    assert_refused(argv, "needs a range for x, r_x", tmp_path)
    assert art.signals["outputs"] == ["x", "theta"]  # the names used above


def test_c_codec_quantises_like_python_bit_for_bit(pend):
    lib, Scale, Layout, Frame = c_codec(load(pend))
    rng = np.random.default_rng(11)
    # (min, max): the pendulum's ranges, an asymmetric one, and one with factor 0.5 where k/2 + 1/4 are exact ties.
    for lo, hi in [(-1.0, 1.0), (-5.0, 5.0), (-0.3, 1.7), (-SPAN / 4, SPAN / 4)]:
        f, o = (hi - lo) / SPAN, (hi + lo) / 2
        scale = Scale(f, o)
        width = hi - lo
        v = np.concatenate(
            [
                rng.uniform(lo - 0.2 * width, hi + 0.2 * width, 20000),
                [lo, hi, o, -0.0, 3e38, -3e38, 1e-40, math.nan, math.inf, -math.inf],
            ]
        ).astype(np.float32)
        if f == 0.5:
            ties = np.arange(-200, 200) / 2 + 0.25
            assert np.all(np.abs((ties - o) / f % 1 - 0.5) == 0)  # really halfway between two raw values
            v = np.concatenate([v, ties.astype(np.float32)])
        py_raw, py_clipped = quantise(v.astype(np.float64), np.full(len(v), f), np.full(len(v), o))
        flag = ctypes.c_int()
        c_raw, c_clipped = np.empty(len(v), np.int16), np.empty(len(v), bool)
        for i, x in enumerate(v):
            c_raw[i] = lib.gl_can_quantise(float(x), ctypes.byref(scale), ctypes.byref(flag))
            c_clipped[i] = flag.value
        assert np.array_equal(c_raw, py_raw) and np.array_equal(c_clipped, py_clipped), (lo, hi)
        assert py_clipped.any() and (py_raw == INT16_NAN).sum() == 3
        assert np.abs(py_raw.astype(int)).max() == INT16_MAX + 1
        # Decoding: the C float is the Python float64 rounded to float32, for every raw value.
        raws = np.arange(-32768, 32768, dtype=np.int32)
        c_phys = np.array([lib.gl_can_dequantise(int(r), ctypes.byref(scale)) for r in raws], dtype=np.float32)
        py_phys = dequantise(raws, f, o).astype(np.float32)
        assert np.array_equal(c_phys.view(np.uint32)[1:], py_phys.view(np.uint32)[1:]) and np.isnan(c_phys[0])

    # Whole frames of the pendulum's layout: C encodes what the Python codec encodes, and decodes it back alike.
    art = load(pend)
    for fd in (False, True):
        layout = _int16(art, fd=fd).layout
        specs = layout.measurement
        codec = FrameCodec(specs, fd=fd)
        scales = (Scale * codec.size)(*[Scale(a, b) for a, b in zip(codec.factors, codec.offsets)])
        c_layout = Layout()
        lib.gl_can_layout_init(ctypes.byref(c_layout), layout.base_id, int(fd), 1)
        assert c_layout.per_frame == layout.per_frame
        _, lo, hi = _value_ranges(art, PENDULUM_RANGES)
        for seq in range(200):
            vals = rng.uniform(lo * 1.1, hi * 1.1).astype(np.float32)
            sat = int(rng.integers(0, 1 << codec.size))
            py_frames = codec.encode(
                seq=seq,
                values=vals.astype(np.float64),
                sat=np.array([(sat >> i) & 1 for i in range(codec.size)], dtype=bool),
            )
            c_vals = (ctypes.c_float * codec.size)(*vals)
            for j, (spec, pf) in enumerate(zip(specs, py_frames)):
                frame = Frame()
                lib.gl_can_layout_encode(
                    ctypes.byref(c_layout),
                    spec.arbitration_id,
                    j,
                    seq,
                    0,
                    sat,
                    c_vals,
                    scales,
                    codec.size,
                    ctypes.byref(frame),
                )
                assert (frame.id, frame.len, frame.fd) == (spec.arbitration_id, len(pf.data), int(fd))
                assert bytes(frame.data[: frame.len]) == bytes(pf.data), (fd, seq, j)
                out, got_seq = (ctypes.c_float * codec.size)(), ctypes.c_uint16()
                assert (
                    lib.gl_can_layout_decode(
                        ctypes.byref(c_layout), j, ctypes.byref(frame), ctypes.byref(got_seq), out, scales, codec.size
                    )
                    == 0
                )
                _, _, _, py_vals = codec.decode(spec.arbitration_id, bytes(pf.data))
                c_out = np.array(out[spec.first : spec.first + len(spec.signals)], dtype=np.float32)
                assert got_seq.value == seq and np.array_equal(c_out, py_vals.astype(np.float32))


def _quantisation_peak_gain(art) -> np.ndarray:
    """Peak-to-peak (l1) gain of the linearised closed loop from each quantisation error to each plant output.

    Plant ``x+ = Ad x + Bd (u + e_u)``, ``y = Cd x``; the controller sees ``y + e_y`` and ``r + e_r`` and runs
    the predictor-form law without saturation. Any error sequence with ``|e_i| <= b_i`` moves output j by at
    most ``sum_i gain[j, i] * b_i`` (the sum of |impulse response|). Columns: e_y (p), e_r (q), e_u (m).
    """
    A, B, C, K, L, Ci, Ki = art.Ad, art.Bd, art.Cd, art.K, art.L, art.Ci, art.Ki
    n, m, p, q, Ts = art.n, art.m, art.p, art.q, art.Ts
    Acl = np.block(
        [[A, -B @ K, -B @ Ki], [L @ C, A - B @ K - L @ C, -B @ Ki], [-Ts * Ci @ C, np.zeros((q, n)), np.eye(q)]]
    )
    Bw = np.block(
        [
            [np.zeros((n, p)), np.zeros((n, q)), B],
            [L, np.zeros((n, q)), np.zeros((n, m))],
            [-Ts * Ci, Ts * np.eye(q), np.zeros((q, m))],
        ]
    )
    Cy = np.hstack([C, np.zeros((p, n + q))])
    assert max(abs(np.linalg.eigvals(Acl))) < 1
    gain, term = np.zeros((p, p + q + m)), Bw
    for _ in range(100000):
        h = np.abs(Cy @ term)
        gain += h
        if h.max() < 1e-14 * gain.max():
            break
        term = Acl @ term
    return gain


def test_int16_lockstep_classic_can_stabilises_the_pendulum_close_to_float32(pend, can_firmware, cart_fmu):
    art = load(pend)
    common = dict(gains=pend, fmu=cart_fmu, duration=8.0)
    runs = {}
    for encoding in ("float32", "int16"):
        transport = {**udp_transport(fd=False), "encoding": encoding, "ranges": PENDULUM_RANGES}
        runs[encoding] = run_scenario(parse_scenario(pendulum_scenario(transport=transport, **common)))
    f32, i16 = runs["float32"], runs["int16"]
    m = i16.metrics
    assert f32.complete and i16.complete and m["lost"] == 0 and m["steps"] == f32.metrics["steps"]
    assert "int16" in i16.info["controller"]["argv"] and i16.info["transport"]["encoding"] == "int16"
    assert i16.info["transport"]["frames_per_sample"] == math.ceil((art.p + art.q) / 2)  # two values per frame
    assert i16.info["transport"]["encoding_clipped"] == 0
    assert abs(m["outputs_final"]["theta"]) < 0.01 and abs(m["outputs_final"]["x"]) < 0.02
    # Closeness to the float32 run. The only difference between the runs is the quantisation: |e| <= factor/2
    # on every measurement, reference and command (float32 rounding is ~1e4 times smaller). For the linearised
    # loop that bounds the output difference by the loop's peak gain times those half steps; the bound holds
    # without saturation (checked), and a factor 2 covers the nonlinear plant's departure from its linear
    # model at |theta| <= 0.1 rad (sin and cos within 0.5 %) with a wide margin.
    assert not i16.trace.sat.any() and not f32.trace.sat.any()
    transport = CanTransport({"interface": "virtual", "encoding": "int16", "ranges": PENDULUM_RANGES}, artifact=art)
    half_steps = np.concatenate([transport.tx.factors, transport.layout.command[0].factors]) / 2
    bound = _quantisation_peak_gain(art) @ half_steps
    diff = np.abs(i16.trace.y - f32.trace.y).max(axis=0)
    assert np.all(diff <= 2 * bound), (diff, bound)
    assert np.all(diff > 0)  # the int16 run really was quantised
    # Against the float64 twin the quantisation shows as the cost it is: the int16 run's output deviation is
    # bounded as above (plus the float32 run's own, tiny, deviation from the twin) and far above float32's.
    dev16 = np.array([v["max_dy"] for v in m["twin"]["outputs"].values()])
    dev32 = np.array([v["max_dy"] for v in f32.metrics["twin"]["outputs"].values()])
    assert np.all(dev16 <= 2 * bound + dev32) and np.all(dev16 > 10 * dev32)
    assert m["encoding_clipped"] == 0


def test_reference_node_speaks_int16_like_the_firmware(pend, can_firmware, cart_fmu):
    common = dict(gains=pend, fmu=cart_fmu, duration=1.5)
    transport = {"encoding": "int16", "ranges": PENDULUM_RANGES}
    fw = run_scenario(parse_scenario(pendulum_scenario(transport={**udp_transport(), **transport}, **common)))
    py = run_scenario(
        parse_scenario(pendulum_scenario(transport={**udp_transport(), **transport}, controller="reference", **common))
    )
    assert fw.complete and py.complete and fw.metrics["lost"] == 0 and py.metrics["lost"] == 0
    # Both quantise the same law's command (float32 in C, float64 in Python): at most a step or so apart.
    layout = CanTransport({"interface": "virtual", **transport}, artifact=load(pend)).layout
    f_u = layout.command[0].factors[0]
    np.testing.assert_allclose(fw.trace.u, py.trace.u, rtol=0, atol=1e-3 + 2 * f_u)
