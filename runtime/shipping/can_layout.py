"""The CAN message layout of one artifact, as a DBC (cantools) and as a fast struct codec.

Every frame starts with a header (wire format 4; :class:`gainlink.shipping.flags.CanHeader` holds its fields, from
which the C, the Python codec and the DBC are made), then its values. In commands the header carries the step's
status flags (the one table of :mod:`gainlink.shipping.flags`, which the DBC carries as the value tables of
``status`` and ``status_hi``) and ``sat`` (bit i set when the i-th value of this command frame was clamped); in
measurements both are 0. Classic CAN and CAN FD differ only in the header:

classic (8-byte frames), 4 bytes
    bytes 0-1 ``seq`` (uint16 LE, the sample counter), byte 2 ``status`` (the flags' bits 0-7), byte 3: its low
    nibble ``sat``, its high nibble ``status_hi`` (the flags' bits 8-11: an MPC's CAPPED, 0x100, is its bit 0). Every
    flag fits beside one float32 value (the nibble would allow 4 values; the 4 bytes left hold 1 float32 or 2 int16).
CAN FD (up to 64 bytes), 8 bytes
    bytes 0-1 ``seq``, byte 2 ``status`` (bits 0-7), byte 3 ``status_hi`` (the flags' bits 8-15: bytes 2-3 are
    the flags as one uint16 LE), bytes 4-7 ``sat`` (uint32 LE). A frame carries up to 14 float32 values (8 + 56 =
    64 bytes) or 28 int16 values.

Values follow the header, little-endian, in one of two encodings:

``float32`` (default)
    IEEE float32, 1 per classic CAN frame (8 bytes), up to 14 per CAN FD frame.
``int16``
    Scaled integers as on a vehicle bus: ``physical = raw * factor + offset`` with, for a value whose
    range is ``[minimum, maximum]``, ``factor = (maximum - minimum) / 65534`` and ``offset = (maximum +
    minimum) / 2``, so raw -32767 .. 32767 spans exactly the range. Encoding rounds half to even
    (``rint``), in float64, on both sides; values beyond the range saturate to its ends (raw +-32767);
    raw -32768 is reserved for a non-finite value (NaN, +-inf) and decodes to NaN, so a non-finite
    sample still reaches the controller's fault path. 2 values per classic frame, up to 28 per FD frame.

Format 3 had the classic header on CAN FD too, so at most 4 values an FD frame: a 16-output sample took 5 FD frames
where format 4 takes 2 (float32) or 1 (int16). FD frame lengths are rounded up to a valid FD length. Command frames
(controller -> plant, ``u``) use ids ``base_id + j``; measurement frames (plant -> controller, ``y`` then ``r``,
then a scheduled artifact's external scheduling signals ``s_NAME``) use ids ``base_id + 0x10 + i``, so commands win
arbitration. The firmware's CAN app implements exactly this rule (its header fields come from ``gl_flags.h``,
generated from the same :class:`~gainlink.shipping.flags.CanHeader`; its int16 factor/offset from
:func:`gainlink.hil.links.can.firmware_can_argv`, i.e. from the same :class:`FrameSpec` data that builds the DBC);
:meth:`CanLayout.dbc` documents it for any CAN tool.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gainlink.errors import TransportError

from .flags import CAN_CLASSIC, CAN_FD, FLAGS, CanHeader, Flag, can_header
from .law_c import externals, law_name

COMMAND_OFFSET = 0x00
MEASUREMENT_OFFSET = 0x10
MAX_COMMAND_FRAMES = MEASUREMENT_OFFSET - COMMAND_OFFSET  # ids base+0x00 .. base+0x0f
MAX_MEASUREMENT_FRAMES = 0x20  # ids base+0x10 .. base+0x2f (the firmware tracks them in a 32-bit mask)
FD_LENGTHS = (8, 12, 16, 20, 24, 32, 48, 64)
ENCODINGS = ("float32", "int16")
#: Which flags of the one table (:data:`gainlink.shipping.flags.FLAGS`, its ``set_by``) each structure's CAN node can
#: set: the DBC's value table and comment of ``status`` name them.
_SET_BY = {
    "lq/float32": ("every law",),
    "lq/q31": ("every law", "fixed point"),
    "lq/q15": ("every law", "fixed point"),
    "scheduled/float32": ("every law", "scheduled"),
    "mpc/float32": ("every law", "mpc"),
}
VALUE_BYTES = {"float32": 4, "int16": 2}
#: Values per frame by encoding (wire format 4: the header's ``sat`` bits and the frame's room).
CLASSIC_VALUES = {enc: CAN_CLASSIC.values(n) for enc, n in VALUE_BYTES.items()}
FD_VALUES = {enc: CAN_FD.values(n) for enc, n in VALUE_BYTES.items()}
#: The struct code of a header read as one little-endian integer, by its size.
_HEADER_CODES = {4: "I", 8: "Q"}
INT16_MAX = 32767  #: largest raw value; -INT16_MAX is the smallest
INT16_NAN = -32768  #: reserved raw value: the value was not finite
INT16_SPAN = 2 * INT16_MAX  #: raw steps across a range


def _sanitize(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return s if re.match(r"[A-Za-z]", s) else f"s_{s}"


@dataclass(frozen=True)
class SignalScale:
    """The physical range of one int16 value and the linear map it implies.

    Attributes
    ----------
    minimum, maximum : float
        Physical range; raw -32767 is ``minimum`` and raw 32767 is ``maximum``.
    """

    minimum: float
    maximum: float

    @property
    def factor(self) -> float:
        """Physical units per raw step: ``(maximum - minimum) / 65534``."""
        return (self.maximum - self.minimum) / INT16_SPAN

    @property
    def offset(self) -> float:
        """Physical value of raw 0: ``(maximum + minimum) / 2``."""
        return (self.maximum + self.minimum) / 2


def quantise(values: np.ndarray, factors: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Raw int16 values of physical ``values`` (the rule of the module docstring).

    Returns
    -------
    raw : numpy.ndarray of int16
        ``rint((value - offset) / factor)`` in float64, clamped to +-32767; -32768 where not finite.
    clipped : numpy.ndarray of bool
        Finite values that were beyond the range (and saturated to its ends).
    """
    v = np.asarray(values, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        x = np.rint((v - offsets) / factors)
    finite = np.isfinite(v)
    clipped = finite & (np.abs(x) > INT16_MAX)
    raw = np.where(
        finite, np.clip(np.nan_to_num(x, posinf=INT16_MAX, neginf=-INT16_MAX), -INT16_MAX, INT16_MAX), INT16_NAN
    )
    return raw.astype(np.int16), clipped


def dequantise(raw: np.ndarray, factors: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Physical float64 values of raw int16 values: ``raw * factor + offset``, NaN for -32768."""
    r = np.asarray(raw, dtype=np.float64)
    return np.where(r == INT16_NAN, np.nan, r * factors + offsets)


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
        DBC names of the values it carries, in order.
    first : int
        Index of its first value in the sample (``y`` then ``r``) or command (``u``) vector.
    length : int
        Payload bytes.
    encoding : {"float32", "int16"}
        How the values are carried.
    scales : tuple of SignalScale
        With ``int16``: the range of each value (same order as ``signals``); empty with ``float32``.
    header : CanHeader
        Its header (classic or CAN FD).
    """

    name: str
    arbitration_id: int
    signals: tuple[str, ...]
    first: int
    length: int
    encoding: str = "float32"
    scales: tuple[SignalScale, ...] = ()
    header: CanHeader = CAN_CLASSIC

    @property
    def value_bytes(self) -> int:
        """Bytes per value (4 or 2)."""
        return VALUE_BYTES[self.encoding]

    @property
    def struct(self) -> struct.Struct:
        """The little-endian struct of the header (one integer: :meth:`CanHeader.pack`) and the values (float32 ``f``
        or raw int16 ``h``), padded to ``length``."""
        k = len(self.signals)
        pad = self.length - self.header.size - self.value_bytes * k
        code = "f" if self.encoding == "float32" else "h"
        return struct.Struct(f"<{_HEADER_CODES[self.header.size]}{k}{code}{pad}x")

    @property
    def factors(self) -> tuple[float, ...]:
        """Per value ``factor`` (int16), as written to the DBC."""
        return tuple(s.factor for s in self.scales)

    @property
    def offsets(self) -> tuple[float, ...]:
        """Per value ``offset`` (int16), as written to the DBC."""
        return tuple(s.offset for s in self.scales)


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
    encoding : {"float32", "int16"}
        How values are carried.
    status_flags : tuple of Flag
        The status flags the artifact's law can set (the DBC's value table and comment of ``status``).
    """

    fd: bool
    base_id: int
    per_frame: int
    measurement: tuple[FrameSpec, ...]
    command: tuple[FrameSpec, ...]
    encoding: str = "float32"
    status_flags: tuple[Flag, ...] = ()

    def database(self) -> Any:
        """The layout as a ``cantools.database.Database``."""
        from cantools.database import Database, Node

        messages = [
            _message(spec, sender=role, receiver=peer, fd=self.fd, status_flags=self._flags_of(role))
            for role, peer, specs in (("controller", "plant", self.command), ("plant", "controller", self.measurement))
            for spec in specs
        ]
        nodes = [
            Node("controller", comment="gainlink firmware (gainlink_can)"),
            Node("plant", comment="gainlink HIL bridge"),
        ]
        dbc = _fd_bus_type() if self.fd else None
        return Database(messages=messages, nodes=nodes, version="gainlink-1", dbc_specifics=dbc)

    def _flags_of(self, sender: str) -> tuple[Flag, ...]:
        """The status flags a sender's frames carry: the controller's commands, none in the plant's samples."""
        return self.status_flags if sender == "controller" else ()

    def dbc(self) -> str:
        """The DBC text of :meth:`database`."""
        return self.database().as_dbc_string()

    def ids(self) -> dict[str, list[int]]:
        """Identifiers by direction."""
        return {
            "command": [s.arbitration_id for s in self.command],
            "measurement": [s.arbitration_id for s in self.measurement],
        }


def _message(spec: FrameSpec, *, sender: str, receiver: str, fd: bool, status_flags: tuple[Flag, ...] = ()) -> Any:
    """The cantools message of one frame."""
    from cantools.database import Message

    return Message(
        frame_id=spec.arbitration_id,
        name=spec.name,
        length=spec.length,
        signals=_header_signals([receiver], header=spec.header, status_flags=status_flags)
        + _value_signals(spec, [receiver]),
        senders=[sender],
        is_fd=fd,
        comment=f"sent by the {sender}",
    )


def _header_signals(rx: list[str], *, header: CanHeader, status_flags: tuple[Flag, ...] = ()) -> list:
    """The header every frame starts with, where ``header`` puts its fields: ``seq``, ``status`` (the flags' bits 0-7;
    its value table: those the law can set, each one bit of the one flag table), ``sat`` (the frame's saturation
    bits) and ``status_hi`` (the flags' bits 8 and up; its value table: those the law can set)."""
    from cantools.database import Signal
    from cantools.database.conversion import BaseConversion

    low = [f for f in status_flags if f.bit < 0x100]
    high = [f for f in status_flags if f.bit >= 0x100]
    choices = {f.bit: f.name for f in low}
    choices_hi = {f.bit >> 8: f.name for f in high}
    meaning = "; ".join(f"bit{f.bit.bit_length() - 1} {f.name}: {f.meaning}" for f in low)
    meaning_hi = "; ".join(f"bit{f.bit.bit_length() - 9} (flag bit {f.bit.bit_length() - 1}) {f.name}: {f.meaning}"
                           for f in high) or "none this law sets"  # fmt: skip
    last_hi = 7 + header.status_hi_bits

    def field(name: str, start: int, length: int, comment: str, choices: dict | None = None) -> Any:
        conversion = BaseConversion.factory(scale=1, offset=0, choices=choices or None, is_float=False)
        return Signal(name, start=start, length=length, byte_order="little_endian", is_signed=False,
                      conversion=conversion, receivers=rx, comment=comment)  # fmt: skip

    return [
        field("seq", 0, 16, "sample counter (wraps at 65536)"),
        field(
            "status",
            16,
            8,
            f"status flags of the step (commands; 0 in samples, gainlink.shipping.flags): {meaning}",
            choices,
        ),
        field("sat", header.sat_start, header.sat_bits, "bit i: i-th value of this frame saturated"),
        field(
            "status_hi",
            header.status_hi_start,
            header.status_hi_bits,
            f"status flags' bits 8-{last_hi} (commands; 0 in samples, gainlink.shipping.flags): {meaning_hi}",
            choices_hi,
        ),
    ]


def _value_signals(spec: FrameSpec, rx: list[str]) -> list:
    """The values a frame carries after its header, in its encoding."""
    at = 8 * spec.header.size
    if spec.encoding == "float32":
        return [_float32_signal(name, at + 32 * i, rx) for i, name in enumerate(spec.signals)]
    return [_int16_signal(name, at + 16 * i, spec.scales[i], rx) for i, name in enumerate(spec.signals)]


def _float32_signal(name: str, start: int, rx: list[str]) -> Any:
    """A value of a frame, at bit ``start``, as an IEEE float32."""
    from cantools.database import Signal
    from cantools.database.conversion import BaseConversion

    return Signal(
        name,
        start=start,
        length=32,
        byte_order="little_endian",
        is_signed=True,
        receivers=rx,
        conversion=BaseConversion.factory(scale=1, offset=0, is_float=True),
    )


def _int16_signal(name: str, start: int, sc: SignalScale, rx: list[str]) -> Any:
    """A value of a frame, at bit ``start``, as a scaled int16 over the range ``sc`` (raw -32768: not a number)."""
    from cantools.database import Signal
    from cantools.database.conversion import BaseConversion

    return Signal(
        name,
        start=start,
        length=16,
        byte_order="little_endian",
        is_signed=True,
        receivers=rx,
        minimum=sc.minimum,
        maximum=sc.maximum,
        conversion=BaseConversion.factory(
            scale=sc.factor, offset=sc.offset, is_float=False, choices={INT16_NAN: "not_a_number"}
        ),
        comment=f"raw {-INT16_MAX}..{INT16_MAX} spans [{sc.minimum:g}, {sc.maximum:g}] "
        f"(beyond: saturated); raw {INT16_NAN}: not a number",
    )


def _fd_bus_type() -> Any:
    """DBC attributes that say the bus is CAN FD (cantools marks the frames CAN FD, VFrameFormat, from them)."""
    from collections import OrderedDict

    from cantools.database.can.formats.dbc.dbc_attribute import DbcAttribute
    from cantools.database.can.formats.dbc.dbc_attribute_definition import DbcAttributeDefinition
    from cantools.database.can.formats.dbc.dbc_specifics import DbcSpecifics

    bus_type = DbcAttributeDefinition("BusType", default_value="CAN", type_name="STRING")
    return DbcSpecifics(
        attributes=OrderedDict(BusType=DbcAttribute("CAN FD", bus_type)),
        attribute_definitions=OrderedDict(BusType=bus_type),
    )


def _frames(
    names: list[str],
    scales: list[SignalScale] | None,
    *,
    prefix: str,
    base: int,
    per_frame: int,
    fd: bool,
    encoding: str,
    max_frames: int,
) -> tuple[FrameSpec, ...]:
    specs = []
    width = VALUE_BYTES[encoding]
    header = can_header(fd)
    for j, first in enumerate(range(0, len(names), per_frame)):
        chunk = tuple(names[first : first + per_frame])
        need = header.size + width * len(chunk)
        length = next(n for n in FD_LENGTHS if n >= need) if fd else 8
        specs.append(
            FrameSpec(
                name=f"{prefix}{j}",
                arbitration_id=base + j,
                signals=chunk,
                first=first,
                length=length,
                encoding=encoding,
                scales=tuple(scales[first : first + per_frame]) if scales is not None else (),
                header=header,
            )
        )
    if len(specs) > max_frames:
        raise TransportError(
            f"CAN layout: {len(names)} {prefix.lower()} values need {len(specs)} frames, more "
            f'than its {max_frames} identifiers (use fd = true or encoding = "int16")'
        )
    return tuple(specs)


def _range(key: str, value: Any) -> SignalScale:
    ok = (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    )
    if not ok or not float(value[0]) < float(value[1]):
        raise TransportError(f"CAN transport: ranges.{key} must be [min, max] with finite min < max, not {value!r}")
    return SignalScale(minimum=float(value[0]), maximum=float(value[1]))


def _scales(
    artifact: Any, ranges: Mapping[str, Any], *, groups: list[tuple[str, list[str], list[str]]], int16: bool
) -> dict[str, list[SignalScale] | None]:
    """Per group (outputs, references, inputs) the range of every value; raises on unknown or missing ones."""
    known: dict[str, list[tuple[str, int]]] = {}
    for group, art_names, dbc_names in groups:
        for i, (a, d) in enumerate(zip(art_names, dbc_names)):
            for key in {a, d}:
                known.setdefault(key, []).append((group, i))
    unknown = [k for k in ranges if k not in known]
    if unknown:
        names = ", ".join(dict.fromkeys(n for _, a, _ in groups for n in a))
        raise TransportError(
            f"CAN transport: ranges name no signal of the artifact: {', '.join(map(str, unknown))} (signals: {names})"
        )
    given: dict[tuple[str, int], SignalScale] = {}
    for key, value in ranges.items():
        sc = _range(key, value)
        for where in known[key]:
            given[where] = sc
    if not int16:
        return {g: None for g, _, _ in groups}
    lo = np.asarray(artifact.u_min, dtype=float).ravel()
    hi = np.asarray(artifact.u_max, dtype=float).ravel()
    out: dict[str, list[SignalScale] | None] = {}
    missing = []
    for group, art_names, _ in groups:
        scales = []
        for i, name in enumerate(art_names):
            sc = given.get((group, i))
            if sc is None and group == "inputs" and math.isfinite(lo[i]) and math.isfinite(hi[i]) and lo[i] < hi[i]:
                sc = SignalScale(minimum=float(lo[i]), maximum=float(hi[i]))
            if sc is None:
                missing.append(name)
            scales.append(sc)
        out[group] = scales
    if missing:
        raise TransportError(
            f"CAN encoding int16 needs a range for {', '.join(missing)}: add ranges = "
            f"{{ {missing[0]} = [min, max], ... }} to the transport table (inputs default to the "
            "artifact's finite u_min/u_max)"
        )
    return out


def layout_for(
    artifact: Any,
    *,
    fd: bool = False,
    base_id: int = 0x100,
    encoding: str = "float32",
    ranges: Mapping[str, Any] | None = None,
) -> CanLayout:
    """The CAN layout of ``artifact`` (its signal names, sizes m, p, q, input limits).

    Parameters
    ----------
    artifact : gainlink.shipping.artifact.Artifact
        The gain artifact.
    fd : bool
        CAN FD (up to 14 float32 or 28 int16 values per frame) instead of classic CAN (1 float32 or 2 int16 values per
        frame).
    base_id : int
        First 11-bit identifier; the layout uses ``base_id .. base_id + 0x2f``.
    encoding : {"float32", "int16"}
        IEEE float32 values, or scaled int16 values (see the module docstring).
    ranges : mapping, optional
        ``{signal: [min, max]}`` by the artifact's signal names (outputs, references, inputs) or the DBC
        names (``y_theta``); a name shared by several values (an output and a reference) covers all of them. Needed with
        ``int16`` for every output and reference, and for inputs whose artifact limits are not finite
        (a range given for an input overrides its limits). Checked with either encoding.

    Raises
    ------
    TransportError
        A bad base_id or encoding, a range that is malformed, names no signal, or is missing.
    """
    ranges = _checked_options(base_id=base_id, encoding=encoding, ranges=ranges)
    sig = artifact.signals
    per_frame = (FD_VALUES if fd else CLASSIC_VALUES)[encoding]
    ys, rs, us = _dbc_names(artifact)
    external, ss = _external_signals(artifact)
    groups = [
        ("outputs", list(sig["outputs"]), ys),
        ("references", list(sig["references"]), rs),
        ("inputs", list(sig["inputs"]), us),
    ]
    if external:
        groups.append(("external", external, ss))
    sc = _scales(artifact, ranges, int16=encoding == "int16", groups=groups)
    meas_scales = None if sc["outputs"] is None else sc["outputs"] + sc["references"] + (sc.get("external") or [])
    common = dict(per_frame=per_frame, fd=fd, encoding=encoding)
    return CanLayout(
        fd=fd,
        base_id=base_id,
        per_frame=per_frame,
        encoding=encoding,
        measurement=_frames(
            ys + rs + ss,
            meas_scales,
            prefix="Measurement",
            base=base_id + MEASUREMENT_OFFSET,
            max_frames=MAX_MEASUREMENT_FRAMES,
            **common,
        ),
        command=_frames(
            us, sc["inputs"], prefix="Command", base=base_id + COMMAND_OFFSET, max_frames=MAX_COMMAND_FRAMES, **common
        ),
        status_flags=status_flags(artifact),
    )


def status_flags(artifact: Any) -> tuple[Flag, ...]:
    """The status flags the artifact's law can set (its CAN node's command frames; the one table's ``set_by``)."""
    return tuple(f for f in FLAGS if f.set_by in _SET_BY[law_name(artifact)])


def _external_signals(artifact: Any) -> tuple[list[str], list[str]]:
    """A scheduled artifact's external scheduling signals (sent after the references, ``s_`` in the DBC): their
    names and DBC names; none for an unscheduled artifact or a sigma read from an output."""
    names = list(externals(artifact))
    return names, [s if s.startswith("s_") else "s_" + s for s in map(_sanitize, names)]


def _checked_options(*, base_id: int, encoding: str, ranges: Mapping[str, Any] | None) -> Mapping[str, Any]:
    """The ranges (empty when none), once ``base_id``, ``encoding`` and the ranges' form are checked."""
    if not 0 <= base_id <= 0x7FF - 0x30:
        raise TransportError(f"CAN base_id {base_id:#x} leaves no room for the layout (0 .. {0x7FF - 0x30:#x})")
    if encoding not in ENCODINGS:
        raise TransportError(f"CAN encoding must be {' or '.join(ENCODINGS)}, not {encoding!r}")
    if ranges is None:
        ranges = {}
    if not isinstance(ranges, Mapping):
        raise TransportError("CAN transport: ranges must be a table { signal = [min, max], ... }")
    return ranges


def _dbc_names(artifact: Any) -> tuple[list[str], list[str], list[str]]:
    """DBC signal names of the outputs, references and inputs: the artifact's names made valid and prefixed
    (``y_``, ``r_``, ``u_``), or ``y0``, ``r0``, ``u0``, ... when that makes two of them equal."""
    sig = artifact.signals

    def named(prefix: str, names: list[str]) -> list[str]:
        return [s if s.startswith(prefix) else prefix + s for s in map(_sanitize, names)]

    ys, rs, us = named("y_", sig["outputs"]), named("r_", sig["references"]), named("u_", sig["inputs"])
    if len(set(ys + rs)) != len(ys + rs) or len(set(us)) != len(us):
        ys, rs = [f"y{i}" for i in range(artifact.p)], [f"r{i}" for i in range(artifact.q)]
        us = [f"u{i}" for i in range(artifact.m)]
    return ys, rs, us
