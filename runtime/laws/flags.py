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

#: MAVLink keeps bits 0-15 of ``HIL_ACTUATOR_CONTROLS.flags`` (bit 0 is its LOCKSTEP flag): gainlink's flags sit at
#: bits 16-23, the saturation mask at bits 32-47.
MAVLINK_FLAGS_SHIFT = 16
MAVLINK_SAT_SHIFT = 32

#: The version of the sample/command wire format (ready lines say ``wire=N``; a peer of another version is refused).
WIRE_VERSION = 2


def names(flags: int) -> list[str]:
    """The names of the flags set in ``flags``, in bit order."""
    return [f.name for f in FLAGS if flags & f.bit]


def c_header() -> str:
    """The C header ``gl_flags.h``: one ``#define GL_FLAG_<NAME>`` per flag, and the MAVLink shifts."""
    lines = [
        "/* DO NOT EDIT: generated from gainlink.laws.flags (the one table of a step's status flags). */",
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
        f"#define GL_WIRE_VERSION {WIRE_VERSION} /**< the sample/command wire format (ready lines: wire=N) */",
        "",
        "#endif /* GAINLINK_GL_FLAGS_H */",
        "",
    ]
    return "\n".join(lines)
