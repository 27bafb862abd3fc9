"""MAVLink parameter encoding, naming scheme and mapping files (no vehicle needed)."""

from __future__ import annotations

import math
import socket
import struct

import numpy as np
import pytest
from gainlink.errors import ParameterError
from gainlink.mavlink.link import MavLink, raw_param_value
from gainlink.mavlink.params import (
    INT32,
    PARAM_TYPES,
    REAL32,
    Encoding,
    as_int32,
    decode_value,
    encode_value,
    firmware_params,
    load_mapping,
    mapped_params,
)
from gainlink.shipping.artifact import load
from hypothesis import given
from hypothesis import strategies as st
from support.cli import assert_refused


@given(st.integers(min_value=-(2**31), max_value=2**31 - 1))
def test_int32_round_trips_bytewise_and_has_its_own_bytes(v):
    raw = encode_value(value=v, ptype=INT32, encoding=Encoding.BYTEWISE)
    assert raw == struct.pack("<i", v)
    assert decode_value(raw=raw, ptype=INT32, encoding=Encoding.BYTEWISE) == v


@given(st.integers(min_value=-(2**24), max_value=2**24))
def test_c_cast_integers_are_their_float_value(v):
    raw = encode_value(value=v, ptype=INT32, encoding=Encoding.C_CAST)
    assert struct.unpack("<f", raw)[0] == float(v)
    assert decode_value(raw=raw, ptype=INT32, encoding=Encoding.C_CAST) == v


@pytest.mark.parametrize(
    "name,value", [("UINT8", 200), ("INT8", -100), ("UINT16", 60000), ("INT16", -30000), ("UINT32", 4_000_000_000)]
)
def test_small_integer_types_round_trip_bytewise(name, value):
    t = PARAM_TYPES[name]
    raw = encode_value(value=value, ptype=t, encoding=Encoding.BYTEWISE)
    assert len(raw) == 4 and decode_value(raw=raw, ptype=t, encoding=Encoding.BYTEWISE) == value
    with pytest.raises(ParameterError, match="does not fit"):
        encode_value(value=-1 if name.startswith("U") else 2**40, ptype=t, encoding=Encoding.BYTEWISE)


def test_a_signalling_nan_bit_pattern_goes_out_exactly():
    """Bytewise integers may look like a NaN; a trip through a Python float would quiet it."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind(("127.0.0.1", 0))
        link = MavLink(f"udpout:127.0.0.1:{rx.getsockname()[1]}")
        try:
            raw = struct.pack("<I", 0x7F800001)  # a signalling NaN as a float
            link.send_param_set(target_system=1, target_component=1, name="GL_HASH", raw=raw, param_type=INT32)
            data = rx.recv(512)
        finally:
            link.close()
    from pymavlink.dialects.v20 import common as mavlink2

    msg = mavlink2.MAVLink(None).decode(bytearray(data))
    assert msg.get_type() == "PARAM_SET" and msg.param_id == "GL_HASH"
    assert bytes(data[10:14]) == raw  # the payload's first field, as sent
    # PARAM_VALUE's bytes are read from the MAVLink 2 frame (pymavlink's get_payload() assumes a v1 header)
    for v in (1.5, 0.0):
        frame = mavlink2.MAVLink_param_value_message(b"GL_TS", v, REAL32, 1, 0).pack(mavlink2.MAVLink(None))
        assert raw_param_value(mavlink2.MAVLink(None).decode(bytearray(frame))) == struct.pack("<f", v)


def test_firmware_naming_scheme(example_artifacts):
    art = load(example_artifacts["pendulum"])
    params = firmware_params(art)
    names = [p.name for p in params]
    assert len(set(names)) == len(names) and all(len(n) <= 16 for n in names)
    by_name = {p.name: p for p in params}
    assert by_name["GL_K_0_3"].value == float(np.float32(art.K[0, 3])) and by_name["GL_K_0_3"].source == "K[0,3]"
    assert by_name["GL_L_3_1"].value == float(np.float32(art.L[3, 1]))
    assert by_name["GL_UMAX_0"].value == 20.0 and by_name["GL_TS"].value == float(np.float32(0.01))
    assert "GL_M_0_0" not in by_name  # predictor form: no current-estimator gain
    assert by_name["GL_DIM_N"].value == 4 and by_name["GL_HASH"].ptype == INT32
    wb = {p.name for p in firmware_params(load(example_artifacts["wood_berry"]))}
    assert {"GL_KI_1_1", "GL_KAW_1_1", "GL_CI_1_1", "GL_Z0_1"} <= wb


def test_as_int32():
    assert as_int32(0xFFFFFFFF) == -1 and as_int32(0x7FFFFFFF) == 2**31 - 1 and as_int32(5) == 5


def test_mapping_file_maps_gains_with_scale_and_types(tmp_path, example_artifacts):
    art = load(example_artifacts["pendulum"])
    path = tmp_path / "map.toml"
    path.write_text(
        '[[param]]\ngain = "K[0,2]"\nname = "ATC_ANG_RLL_P"\nscale = -0.5\n'
        '[[param]]\ngain = "u_max[0]"\nname = "MOT_LIM"\ntype = "int16"\nscale = 10\n'
        '[[param]]\ngain = "Ts"\nname = "SCHED_DT"\n'
    )
    specs = mapped_params(art, load_mapping(path))
    assert [(s.name, s.ptype) for s in specs] == [("ATC_ANG_RLL_P", REAL32), ("MOT_LIM", 4), ("SCHED_DT", REAL32)]
    assert specs[0].value == float(np.float32(-0.5 * art.K[0, 2]))
    assert specs[1].value == 200 and math.isclose(specs[2].value, 0.01, rel_tol=1e-7)


@pytest.mark.parametrize(
    "text,message",
    [
        ('[[param]]\ngain = "K[0,9]"\nname = "X"\n', "out of range"),
        ('[[param]]\ngain = "Q[0,0]"\nname = "X"\n', "unknown gain"),
        ('[[param]]\ngain = "K[0,0]"\nname = "THIS_ID_IS_TOO_LONG"\n', "invalid parameter id"),
        ('[[param]]\ngain = "K[0,0]"\nname = "X"\ntype = "REAL64"\n', "unknown type"),
        ('[[param]]\ngain = "K[0,0]"\nname = "X"\n[[param]]\ngain = "K[0,1]"\nname = "X"\n', "mapped twice"),
        ('[[param]]\ngain = "K[0,0]"\n', "lacks 'name'"),
        ('[[param]]\ngain = "K[0,0]"\nname = "X"\nunit = "s"\n', "unknown key"),
        ("[vehicle]\nx = 1\n", "unknown table"),
        ("param = [", "not valid TOML"),
        ('[[param]]\ngain = "u_max[0]"\nname = "X"\ntype = "INT8"\nscale = 100\n', "does not fit"),
    ],
)
def test_bad_mapping_files_are_one_line_errors_before_any_link(tmp_path, example_artifacts, text, message):
    path = tmp_path / "map.toml"
    path.write_text(text)
    argv = ("mavlink", "upload", example_artifacts["pendulum"], "--connect", "udpout:127.0.0.1:9", "--mapping", path)
    assert_refused((*argv, "--heartbeat-timeout", "0.2"), message, tmp_path)


def test_bad_upload_arguments(example_artifacts, tmp_path):
    pend = example_artifacts["pendulum"]
    assert_refused(
        ("mavlink", "upload", pend, "--connect", "udpout:127.0.0.1:9", "--window", "0"), "--window", tmp_path
    )
    missing = ("mavlink", "upload", tmp_path / "missing.json", "--connect", "udpout:127.0.0.1:9")
    assert_refused(missing, "missing.json", tmp_path)
    assert_refused(("mavlink", "upload", pend), "--connect", tmp_path)
