"""The status flags of a step: one table for every law, link and language.

A command answers one sample; its flags say what the law did with that sample. The bits are the same in the
Python step result (:class:`~gainlink.laws.base.Step`), in the C (``gl_flags.h``, generated from this table), in
the CAN command frames' status byte (and the DBC's value table) and in MAVLink's ``HIL_ACTUATOR_CONTROLS.flags``
(shifted above MAVLink's own bits: :data:`MAVLINK_FLAGS_SHIFT`). Which laws can set a flag is part of the table, so
a link or a report never needs to know which law it carries to read them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Flag:
    """One status flag: its C/Python name, bit value, meaning and the structures/formats that can set it."""

    name: str
    bit: int
    meaning: str
    set_by: str


FLAGS: tuple[Flag, ...] = (
    Flag("FAULT", 0x01, "a non-finite sample or reference was refused: the safe command, state untouched", "every law"),
    Flag("WATCHDOG", 0x02, "no sample for the watchdog's periods: the safe command until the next sample", "every law"),
    Flag("CLIPPED", 0x04, "a sample or reference outside its declared range was clipped to it", "fixed point"),
    Flag("OVERFLOW", 0x08, "the second-line saturation had to clip (certified never to in range)", "fixed point"),
    Flag("SIGMA_HELD", 0x10, "sigma was not finite: the last valid sigma was used", "scheduled"),
    Flag("SIGMA_CLIPPED", 0x20, "sigma was outside the envelope and was clipped to it", "scheduled"),
    Flag("SIGMA_RATE", 0x40, "sigma's change was limited to Ts * rate_max", "scheduled"),
    Flag("RESET", 0x80, "the law was reset: the command is its start command", "every law"),
    Flag("CAPPED", 0x100, "the solver's iteration cap stopped it: the projected first move was applied", "mpc"),
)

#: Each flag's bit by name.
BITS: dict[str, int] = {f.name: f.bit for f in FLAGS}

FAULT = BITS["FAULT"]
WATCHDOG = BITS["WATCHDOG"]
CLIPPED = BITS["CLIPPED"]
OVERFLOW = BITS["OVERFLOW"]
SIGMA_HELD = BITS["SIGMA_HELD"]
SIGMA_CLIPPED = BITS["SIGMA_CLIPPED"]
SIGMA_RATE = BITS["SIGMA_RATE"]
RESET = BITS["RESET"]
CAPPED = BITS["CAPPED"]

#: MAVLink keeps bits 0-15 of ``HIL_ACTUATOR_CONTROLS.flags`` (bit 0 is its LOCKSTEP flag): gainlink's flags sit at
#: bits 16-31 (the table's bits 0-15: CAPPED, 0x100, at bit 24), the saturation mask at bits 32-47.
MAVLINK_FLAGS_SHIFT = 16
MAVLINK_SAT_SHIFT = 32


@dataclass(frozen=True)
class CanHeader:
    """Where a CAN frame's header puts its fields: bit fields of one little-endian integer of ``size`` bytes,
    numbered as a DBC numbers a little-endian signal's bits (bit ``8 * b + i`` is bit i of byte b).

    Every header has ``seq`` at bits 0-15 and the flags' bits 0-7 (``status``) at bits 16-23; the flags' bits
    8 .. 8 + ``status_hi_bits`` - 1 sit at ``status_hi_start`` (``status_hi``), the frame's saturation bits (bit i:
    the frame's i-th value) at ``sat_start`` (``sat``, ``sat_bits`` wide). The C (``gl_flags.h``), the Python codec
    and the DBC read these numbers, never their own copies.
    """

    kind: str
    size: int
    status_hi_start: int
    status_hi_bits: int
    sat_start: int
    sat_bits: int
    max_frame: int

    @property
    def status_mask(self) -> int:
        """The flags' bits the header carries."""
        return (1 << (8 + self.status_hi_bits)) - 1

    def values(self, value_bytes: int) -> int:
        """Values a frame carries: one ``sat`` bit each, within the frame's ``max_frame`` bytes."""
        return min(self.sat_bits, (self.max_frame - self.size) // value_bytes)

    def pack(self, seq: int, status: int, sat: int) -> int:
        """The header as one integer (little-endian on the wire): ``seq``, the flags ``status`` (the bits beyond the
        header's dropped) and the frame's saturation bits ``sat``."""
        return (
            (seq & 0xFFFF)
            | (status & 0xFF) << 16
            | ((status >> 8) & ((1 << self.status_hi_bits) - 1)) << self.status_hi_start
            | (sat & ((1 << self.sat_bits) - 1)) << self.sat_start
        )

    def unpack(self, word: int) -> tuple[int, int, int]:
        """``(seq, status, sat)`` of a header read as one integer: the inverse of :meth:`pack`."""
        hi = (word >> self.status_hi_start) & ((1 << self.status_hi_bits) - 1)
        return word & 0xFFFF, (word >> 16) & 0xFF | hi << 8, (word >> self.sat_start) & ((1 << self.sat_bits) - 1)


#: Wire format 4. A classic frame (8 bytes) keeps format 3's 4-byte header: byte 2 the flags' bits 0-7, byte 3's low
#: nibble the frame's saturation bits and its high nibble the flags' bits 8-11 (CAPPED, 0x100, is its bit 0), so
#: every flag fits beside one float32 value.
CAN_CLASSIC = CanHeader("classic", size=4, status_hi_start=28, status_hi_bits=4, sat_start=24, sat_bits=4, max_frame=8)
#: A CAN FD frame (up to 64 bytes) has an 8-byte header: bytes 2-3 the flags' bits 0-15 (uint16 LE: byte 3 is
#: ``status_hi``), bytes 4-7 the frame's saturation bits (uint32 LE), so 14 float32 or 28 int16 values a frame.
CAN_FD = CanHeader("fd", size=8, status_hi_start=24, status_hi_bits=8, sat_start=32, sat_bits=32, max_frame=64)


def can_header(fd: bool) -> CanHeader:
    """The header of a CAN FD frame, or of a classic one."""
    return CAN_FD if fd else CAN_CLASSIC


#: The version of the sample/command wire format (ready lines say ``wire=N``; a peer of another version is refused).
#: 3: the CAN frames' byte 3 carried the status bits 8-11 in its high nibble, and any frame at most 4 values.
#: 4: classic frames as in 3; CAN FD frames have the 8-byte header of :data:`CAN_FD` (14 float32 / 28 int16 values).
WIRE_VERSION = 4


def names(flags: int) -> list[str]:
    """The names of the flags set in ``flags``, in bit order."""
    return [f.name for f in FLAGS if flags & f.bit]


def c_header() -> str:
    """The C header ``gl_flags.h``: one ``#define GL_FLAG_<NAME>`` per flag, the MAVLink shifts, the CAN headers'
    fields (``GL_CAN_CLASSIC_*``, ``GL_CAN_FD_*``) and the wire format."""
    lines = [
        "/* DO NOT EDIT — generated by gainlink export: structure only, from gainlink.shipping.flags (the one "
        "table of a step's status flags). */",
        "#ifndef GAINLINK_GL_FLAGS_H",
        "#define GAINLINK_GL_FLAGS_H",
        "",
    ]
    for f in FLAGS:
        lines.append(f"#define GL_FLAG_{f.name} 0x{f.bit:02x}u /**< {f.meaning} ({f.set_by}) */")
    lines += [
        "",
        f"#define GL_FLAGS_MAVLINK_SHIFT {MAVLINK_FLAGS_SHIFT} /**< gainlink's flags in HIL_ACTUATOR_CONTROLS.flags */",
        f"#define GL_SAT_MAVLINK_SHIFT {MAVLINK_SAT_SHIFT} /**< the saturation mask in HIL_ACTUATOR_CONTROLS.flags */",
        *_can_header_defines(CAN_CLASSIC),
        *_can_header_defines(CAN_FD),
        f"#define GL_WIRE_VERSION {WIRE_VERSION} /**< the sample/command wire format (ready lines: wire=N) */",
        f'#define GL_WIRE_VERSION_TEXT "{WIRE_VERSION}" /**< the same as text */',
        "",
        "#endif /* GAINLINK_GL_FLAGS_H */",
        "",
    ]
    return "\n".join(lines)


def _can_header_defines(h: CanHeader) -> list[str]:
    """The ``GL_CAN_<KIND>_*`` defines of a CAN header (gl_can_layout.c encodes and decodes with them)."""
    k = f"GL_CAN_{h.kind.upper()}"
    return [
        f"#define {k}_HEADER {h.size}u /**< header bytes of a {h.kind} frame (wire format {WIRE_VERSION}) */",
        f"#define {k}_STATUS_HI_START {h.status_hi_start}u /**< bit of the header where the flags' bit 8 sits */",
        f"#define {k}_STATUS_HI_BITS {h.status_hi_bits}u /**< the flags' bits 8.. the header carries */",
        f"#define {k}_SAT_START {h.sat_start}u /**< bit of the header where the frame's saturation bits start */",
        f"#define {k}_SAT_BITS {h.sat_bits}u /**< saturation bits: at most this many values a frame */",
        f"#define {k}_MAX_FRAME {h.max_frame}u /**< largest frame */",
    ]
