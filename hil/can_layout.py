"""The CAN message layout of one artifact, as a DBC (cantools) and as a fast struct codec.

Every frame starts with a 4-byte header: ``seq`` (uint16, little-endian sample counter), ``status``
(uint8, ``STATUS_*`` bits in commands, 0 in measurements) and ``sat`` (uint8, bit i set when the
i-th value of this command frame was clamped). Values follow as IEEE float32, little-endian,
``per_frame`` of them: 1 per classic CAN frame (8 bytes), up to 8 per CAN FD frame (the frame
length is rounded up to a valid FD length). Command frames (controller -> plant, ``u``) use ids
``base_id + j``; measurement frames (plant -> controller, ``y`` then ``r``) use ids
``base_id + 0x10 + i``, so commands win arbitration. The firmware's CAN app implements exactly
this rule; :meth:`CanLayout.dbc` documents it for any CAN tool.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any

from gainlink.errors import TransportError

HEADER_BYTES = 4
COMMAND_OFFSET = 0x00
MEASUREMENT_OFFSET = 0x10
FD_MAX_VALUES = 8
FD_LENGTHS = (8, 12, 16, 20, 24, 32, 48, 64)


def _sanitize(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return s if re.match(r"[A-Za-z]", s) else f"s_{s}"


@dataclass(frozen=True)
class FrameSpec:
    """One CAN frame of the layout.

    Attributes
    ----------
    name : str
        DBC message name.
    arbitration_id : int
        11-bit identifier.
    signals : tuple of str
        DBC names of the float values it carries, in order.
    first : int
        Index of its first value in the sample (``y`` then ``r``) or command (``u``) vector.
    length : int
        Payload bytes.
    """

    name: str
    arbitration_id: int
    signals: tuple[str, ...]
    first: int
    length: int

    @property
    def struct(self) -> struct.Struct:
        """The little-endian struct of header + values, padded to ``length``."""
        pad = self.length - HEADER_BYTES - 4 * len(self.signals)
        return struct.Struct(f"<HBB{len(self.signals)}f{pad}x")


@dataclass(frozen=True)
class CanLayout:
    """All frames exchanged for one artifact.

    Attributes
    ----------
    fd : bool
        CAN FD frames (else classic CAN, 8 bytes).
    base_id : int
        First identifier used.
    per_frame : int
        Values per frame.
    measurement, command : tuple of FrameSpec
        Plant -> controller frames (``y`` then ``r``), controller -> plant frames (``u``).
    """

    fd: bool
    base_id: int
    per_frame: int
    measurement: tuple[FrameSpec, ...]
    command: tuple[FrameSpec, ...]

    def database(self) -> Any:
        """The layout as a ``cantools.database.Database``."""
        from cantools.database import Database, Message, Node, Signal
        from cantools.database.conversion import BaseConversion

        def signals(spec: FrameSpec, receiver: str) -> list:
            rx = [receiver]
            sig = [
                Signal("seq", start=0, length=16, byte_order="little_endian", is_signed=False, receivers=rx,
                       comment="sample counter (wraps at 65536)"),
                Signal("status", start=16, length=8, byte_order="little_endian", is_signed=False, receivers=rx,
                       comment="bit0 fault (non-finite sample), bit1 watchdog"),
                Signal("sat", start=24, length=8, byte_order="little_endian", is_signed=False, receivers=rx,
                       comment="bit i: i-th value of this frame saturated"),
            ]
            for i, name in enumerate(spec.signals):
                sig.append(Signal(name, start=32 + 32 * i, length=32, byte_order="little_endian", is_signed=True,
                                  receivers=rx, conversion=BaseConversion.factory(scale=1, offset=0, is_float=True)))
            return sig

        messages = []
        for role, peer, specs in (("controller", "plant", self.command), ("plant", "controller", self.measurement)):
            for spec in specs:
                messages.append(Message(frame_id=spec.arbitration_id, name=spec.name, length=spec.length,
                                        signals=signals(spec, peer), senders=[role], is_fd=self.fd,
                                        comment=f"sent by the {role}"))
        dbc = None
        if self.fd:  # cantools marks frames CAN FD (VFrameFormat) when the bus type attribute says so
            from collections import OrderedDict

            from cantools.database.can.formats.dbc.dbc_attribute import DbcAttribute
            from cantools.database.can.formats.dbc.dbc_attribute_definition import DbcAttributeDefinition
            from cantools.database.can.formats.dbc.dbc_specifics import DbcSpecifics

            bus_type = DbcAttributeDefinition("BusType", default_value="CAN", type_name="STRING")
            dbc = DbcSpecifics(attributes=OrderedDict(BusType=DbcAttribute("CAN FD", bus_type)),
                               attribute_definitions=OrderedDict(BusType=bus_type))
        nodes = [Node("controller", comment="gainlink firmware (gainlink_can)"),
                 Node("plant", comment="gainlink HIL bridge")]
        return Database(messages=messages, nodes=nodes, version="gainlink-1", dbc_specifics=dbc)

    def dbc(self) -> str:
        """The DBC text of :meth:`database`."""
        return self.database().as_dbc_string()

    def ids(self) -> dict[str, list[int]]:
        """Identifiers by direction."""
        return {"command": [s.arbitration_id for s in self.command],
                "measurement": [s.arbitration_id for s in self.measurement]}


def _frames(names: list[str], *, prefix: str, base: int, per_frame: int, fd: bool) -> tuple[FrameSpec, ...]:
    specs = []
    for j, first in enumerate(range(0, len(names), per_frame)):
        chunk = tuple(names[first:first + per_frame])
        need = HEADER_BYTES + 4 * len(chunk)
        length = next(n for n in FD_LENGTHS if n >= need) if fd else 8
        specs.append(FrameSpec(name=f"{prefix}{j}", arbitration_id=base + j, signals=chunk, first=first, length=length))
    return tuple(specs)


def layout_for(artifact: Any, *, fd: bool = False, base_id: int = 0x100) -> CanLayout:
    """The CAN layout of ``artifact`` (its signal names, sizes m, p, q).

    Parameters
    ----------
    artifact : gainlink.artifact.Artifact
        The gain artifact.
    fd : bool
        CAN FD (up to 8 values per frame) instead of classic CAN (one value per frame).
    base_id : int
        First 11-bit identifier; the layout uses ``base_id .. base_id + 0x2f``.
    """
    if not 0 <= base_id <= 0x7FF - 0x30:
        raise TransportError(f"CAN base_id {base_id:#x} leaves no room for the layout (0 .. {0x7FF - 0x30:#x})")
    sig = artifact.signals
    per_frame = FD_MAX_VALUES if fd else 1
    def named(prefix: str, names: list[str]) -> list[str]:
        return [s if s.startswith(prefix) else prefix + s for s in map(_sanitize, names)]

    meas = named("y_", sig["outputs"]) + named("r_", sig["references"])
    cmd = named("u_", sig["inputs"])
    if len(set(meas)) != len(meas) or len(set(cmd)) != len(cmd):
        meas = [f"y{i}" for i in range(artifact.p)] + [f"r{i}" for i in range(artifact.q)]
        cmd = [f"u{i}" for i in range(artifact.m)]
    return CanLayout(
        fd=fd, base_id=base_id, per_frame=per_frame,
        measurement=_frames(meas, prefix="Measurement", base=base_id + MEASUREMENT_OFFSET, per_frame=per_frame, fd=fd),
        command=_frames(cmd, prefix="Command", base=base_id + COMMAND_OFFSET, per_frame=per_frame, fd=fd),
    )
