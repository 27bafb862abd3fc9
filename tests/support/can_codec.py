"""The firmware's CAN layout codec (``firmware/apps/can/gl_can_layout.c``, the code the host CAN node and the
Cortex-M images' slcan node frame their samples and commands with) as a library the tests call through ctypes."""

from __future__ import annotations

import ctypes
from typing import Any

from gainlink.firmware.build import host_app


def c_codec(artifact: Any) -> tuple[Any, Any, Any, Any]:
    """The firmware's gl_can_layout.c (the host CAN node's codec), built by the firmware's CMake for ``artifact`` as
    a shared library (the host apps' tree's target gainlink_can_layout), through ctypes: ``(lib, Scale, Layout,
    Frame)``, the library and its structs."""

    class Scale(ctypes.Structure):
        _fields_ = [("factor", ctypes.c_double), ("offset", ctypes.c_double)]

    class Layout(ctypes.Structure):
        _fields_ = [
            ("base_id", ctypes.c_uint32),
            ("fd", ctypes.c_int),
            ("encoding", ctypes.c_int),
            ("per_frame", ctypes.c_uint32),
            ("value_bytes", ctypes.c_uint32),
            ("header", ctypes.c_uint32),
            ("status_hi_start", ctypes.c_uint32),
            ("status_hi_bits", ctypes.c_uint32),
            ("sat_start", ctypes.c_uint32),
            ("sat_bits", ctypes.c_uint32),
            ("max_frame", ctypes.c_uint32),
        ]

    class Frame(ctypes.Structure):
        _fields_ = [
            ("id", ctypes.c_uint32),
            ("len", ctypes.c_uint8),
            ("fd", ctypes.c_uint8),
            ("data", ctypes.c_uint8 * 64),
        ]

    so = host_app(artifact, target="gainlink_can_layout", relpath="apps/can/libgainlink_can_layout.so")
    lib = ctypes.CDLL(str(so))
    lib.gl_can_quantise.restype = ctypes.c_int16
    lib.gl_can_quantise.argtypes = [ctypes.c_float, ctypes.POINTER(Scale), ctypes.POINTER(ctypes.c_int)]
    lib.gl_can_dequantise.restype = ctypes.c_float
    lib.gl_can_dequantise.argtypes = [ctypes.c_int16, ctypes.POINTER(Scale)]
    lib.gl_can_layout_init.argtypes = [ctypes.POINTER(Layout), ctypes.c_uint32, ctypes.c_int, ctypes.c_int]
    lib.gl_can_layout_encode.restype = ctypes.c_uint32
    lib.gl_can_layout_encode.argtypes = [
        ctypes.POINTER(Layout),
        ctypes.c_uint32,
        ctypes.c_uint32,
        ctypes.c_uint16,
        ctypes.c_uint16,
        ctypes.c_uint32,
        ctypes.POINTER(ctypes.c_float),
        ctypes.POINTER(Scale),
        ctypes.c_uint32,
        ctypes.POINTER(Frame),
    ]
    lib.gl_can_layout_header.restype = ctypes.c_int
    lib.gl_can_layout_header.argtypes = [
        ctypes.POINTER(Layout),
        ctypes.POINTER(Frame),
        ctypes.POINTER(ctypes.c_uint16),
        ctypes.POINTER(ctypes.c_uint16),
        ctypes.POINTER(ctypes.c_uint32),
    ]
    lib.gl_can_layout_decode.restype = ctypes.c_int
    lib.gl_can_layout_decode.argtypes = [
        ctypes.POINTER(Layout),
        ctypes.c_uint32,
        ctypes.POINTER(Frame),
        ctypes.POINTER(ctypes.c_uint16),
        ctypes.POINTER(ctypes.c_float),
        ctypes.POINTER(Scale),
        ctypes.c_uint32,
    ]
    return lib, Scale, Layout, Frame
