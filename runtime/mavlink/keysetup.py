"""Give a vehicle its MAVLink 2 signing key with SETUP_SIGNING, and check that it signs with it.

MAVLink has no acknowledgement of SETUP_SIGNING: after sending it, the link switches to the new key and asks
for AUTOPILOT_VERSION; only an answer correctly signed with the new key (pymavlink checks it) proves the
vehicle took it. A first key is sent unsigned, which a vehicle should take only on a link it trusts (the
firmware: the Cortex-M image's UART, a cable; never UDP); a key is replaced by a SETUP_SIGNING signed with
the current one.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink2

from ..errors import TransportError
from . import signing
from .link import MavLink
from .params import Encoding
from .session import ParamSession

MAVLINK_EPOCH_S = 1420070400
"""2015-01-01 00:00:00 UTC, the origin of MAVLink 2 signing timestamps."""


class KeyNotTakenError(TransportError):
    """The vehicle did not answer signed with the new key after SETUP_SIGNING."""


@dataclass(frozen=True)
class KeySetup:
    """Outcome of :func:`setup_signing`.

    Attributes
    ----------
    target : tuple of int
        The vehicle's (system, component).
    replaced : bool
        The SETUP_SIGNING was signed with a current key (a key change) rather than sent unsigned.
    """

    target: tuple[int, int]
    replaced: bool


def signing_timestamp(now: float | None = None) -> int:
    """``now`` (default: the clock) in signing units: 10 us since 2015-01-01 UTC."""
    return max(0, int(((time.time() if now is None else now) - MAVLINK_EPOCH_S) * 100_000))


def setup_signing(
    connect: str, key: bytes, *, current: bytes | None = None, heartbeat_timeout: float = 5.0, timeout: float = 2.0
) -> KeySetup:
    """Send SETUP_SIGNING with ``key`` to the vehicle on ``connect`` and check that it signs with it.

    Parameters
    ----------
    connect : str
        pymavlink URL of the vehicle (``tcp:HOST:PORT`` for the image's UART in QEMU, a serial device, UDP).
    key : bytes
        The new 32-byte key.
    current : bytes, optional
        The key the vehicle has now: the SETUP_SIGNING is signed with it. Without it, it goes unsigned.
    heartbeat_timeout : float
        Seconds to wait for the vehicle's heartbeat.
    timeout : float
        Seconds to wait for each of three AUTOPILOT_VERSION requests signed with the new key.

    Returns
    -------
    KeySetup

    Raises
    ------
    KeyNotTakenError
        No answer signed with ``key`` came back (one line: why a vehicle refuses one).
    PeerTimeoutError
        No heartbeat.
    """
    if len(key) != signing.KEY_BYTES:
        raise signing.SigningKeyError(f"a signing key has {signing.KEY_BYTES} bytes, not {len(key)}")
    with MavLink(connect, signing_key=current) as link:
        hb = link.wait_heartbeat(timeout=heartbeat_timeout)
        target = (hb.get_srcSystem(), hb.get_srcComponent())
        link.send(mavlink2.MAVLink_setup_signing_message(*target, list(key), signing_timestamp()))
        signing.enable(link.mav, key, allow_unsigned=signing.heartbeat_only)  # the same link, in order
        session = ParamSession(link, target_system=target[0], target_component=target[1], encoding=Encoding.BYTEWISE)
        answer = session.request_message(msg_id=mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION, wait=timeout)
    if answer is None:
        how = "signed with the key given as current" if current is not None else "unsigned"
        raise KeyNotTakenError(
            f"vehicle {target[0]}/{target[1]} on {connect} does not sign with the new key after a SETUP_SIGNING "
            f"sent {how} (a first key is taken only on a trusted link, e.g. the image's UART; to replace a key, "
            "give the current one with --signing-key)"
        )
    return KeySetup(target=target, replaced=current is not None)
