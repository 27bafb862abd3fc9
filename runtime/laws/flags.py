"""The status flags of a step (:mod:`gainlink.shipping.flags`, where the one table is defined): the names every
layer above the C export uses. The table lives below the export because the export writes it as C (``gl_flags.h``)
and the CAN DBC's value table comes from it too."""

from __future__ import annotations

from ..shipping.flags import (
    BITS,
    CAN_CLASSIC,
    CAN_FD,
    CAPPED,
    CLIPPED,
    FAULT,
    FLAGS,
    MAVLINK_FLAGS_SHIFT,
    MAVLINK_SAT_SHIFT,
    OVERFLOW,
    RESET,
    SIGMA_CLIPPED,
    SIGMA_HELD,
    SIGMA_RATE,
    WATCHDOG,
    WIRE_VERSION,
    CanHeader,
    Flag,
    c_header,
    can_header,
    names,
)

__all__ = [
    "BITS",
    "CAN_CLASSIC",
    "CAN_FD",
    "CAPPED",
    "CLIPPED",
    "FAULT",
    "FLAGS",
    "MAVLINK_FLAGS_SHIFT",
    "MAVLINK_SAT_SHIFT",
    "OVERFLOW",
    "RESET",
    "SIGMA_CLIPPED",
    "SIGMA_HELD",
    "SIGMA_RATE",
    "WATCHDOG",
    "WIRE_VERSION",
    "CanHeader",
    "Flag",
    "c_header",
    "can_header",
    "names",
]
