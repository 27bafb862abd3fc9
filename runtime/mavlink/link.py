"""A MAVLink 2 link on a pymavlink connection URL, with the framing done by pymavlink.

pymavlink's ``mavutil`` opens the device (``udpin:``, ``udpout:``, ``tcp:``, serial paths); the
MAVLink 2 ``common`` dialect object frames and parses. The protocol version is fixed here, not
chosen by pymavlink's ``MAVLINK20`` environment variable.
"""

from __future__ import annotations

import logging
import struct
import time

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from ..errors import PeerTimeoutError, TransportError
from . import signing

log = logging.getLogger(__name__)

#: Component id used by gainlink's ground tools (MAV_COMP_ID_MISSIONPLANNER).
GCS_COMPONENT = mavlink2.MAV_COMP_ID_MISSIONPLANNER


class _ParamSetRaw(mavlink2.MAVLink_param_set_message):
    """PARAM_SET whose ``param_value`` bytes are given exactly (bytewise integers may be NaN patterns
    that a round trip through a Python float would alter)."""

    def __init__(self, *, target_system: int, target_component: int, param_id: str, raw: bytes, param_type: int):
        super().__init__(target_system, target_component, param_id.encode("ascii"), 0.0, param_type)
        self._raw = bytes(raw[:4]).ljust(4, b"\0")

    def pack(self, mav: mavlink2.MAVLink, force_mavlink1: bool = False) -> bytes:
        payload = self._raw + struct.pack(
            "<BB16sB", self.target_system, self.target_component, self._param_id_raw, self.param_type
        )
        return self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)


def raw_param_value(msg: mavlink2.MAVLink_param_value_message) -> bytes:
    """The four ``param_value`` bytes of a received PARAM_VALUE, exactly as sent.

    Read from the frame itself (pymavlink's ``get_payload()`` assumes a MAVLink 1 header).
    """
    buf = bytes(msg.get_msgbuf())
    start = 10 if buf[0] == 0xFD else 6
    payload = buf[start : start + buf[1]]
    return (payload + bytes(4))[:4]


def carries_signature(msg: mavlink2.MAVLink_message) -> bool:
    """Whether ``msg`` arrived with a MAVLink 2 signature, checked or not (``get_signed()`` is true only for a
    signature checked with our key; a link without a key takes signed messages unchecked)."""
    return bool(msg.get_header().incompat_flags & mavlink2.MAVLINK_IFLAG_SIGNED)


def _no_heartbeat(
    url: str, timeout: float, system: int | None, component: int | None, heard: set[tuple[int, int]]
) -> str:
    """Why :meth:`MavLink.wait_heartbeat` gave up: the vehicle asked for and the others heard instead."""
    if system is None and component is None:
        return f"no heartbeat on {url} within {timeout:g} s"
    want = f"{'*' if system is None else system}/{'*' if component is None else component}"
    others = ", ".join(f"{s}/{c}" for s, c in sorted(heard)) or "none"
    return f"no heartbeat from vehicle {want} on {url} within {timeout:g} s (other vehicles heard: {others})"


class MavLink:
    """One MAVLink 2 endpoint.

    Parameters
    ----------
    url : str
        A pymavlink connection string: ``udpin:127.0.0.1:14550``, ``udpout:127.0.0.1:14550``,
        ``tcp:host:port``, ``/dev/ttyACM0`` (``baud`` applies).
    source_system, source_component : int
        Our own MAVLink ids.
    baud : int
        Baud rate for serial devices.
    signing_key : bytes, optional
        A 32-byte MAVLink 2 signing key (:func:`gainlink.mavlink.signing.read_key`): everything sent is signed,
        and only correctly signed messages are taken (a vehicle's unsigned HEARTBEAT is let through only so
        :meth:`wait_heartbeat` can say that it does not sign).
    link_id : int
        Signing link id of this session.
    """

    def __init__(
        self,
        url: str,
        *,
        source_system: int = 255,
        source_component: int = GCS_COMPONENT,
        baud: int = 115200,
        signing_key: bytes | None = None,
        link_id: int = 1,
    ):
        self.url = url
        try:
            self.conn = mavutil.mavlink_connection(
                url, baud=baud, source_system=source_system, source_component=source_component, autoreconnect=False
            )
        except (OSError, ValueError) as exc:
            raise TransportError(f"cannot open MAVLink link {url!r}: {exc}") from None
        self.mav = mavlink2.MAVLink(self.conn, srcSystem=source_system, srcComponent=source_component)
        self.mav.robust_parsing = True
        self.signed = signing_key is not None
        if signing_key is not None:
            signing.enable(self.mav, signing_key, link_id=link_id, allow_unsigned=signing.heartbeat_only)
        self.rx_count = 0
        self.tx_count = 0

    def send(self, msg: mavlink2.MAVLink_message) -> None:
        """Frame and send one message."""
        try:
            self.mav.send(msg)
        except OSError as exc:
            raise TransportError(f"MAVLink send on {self.url!r} failed: {exc}") from None
        self.tx_count += 1

    def send_param_set(
        self, *, target_system: int, target_component: int, name: str, raw: bytes, param_type: int
    ) -> None:
        """Send PARAM_SET with the exact four value bytes ``raw``."""
        self.send(
            _ParamSetRaw(
                target_system=target_system,
                target_component=target_component,
                param_id=name,
                raw=raw,
                param_type=param_type,
            )
        )

    def poll(self, timeout: float) -> list:
        """Return the messages that arrive within ``timeout`` seconds (as soon as there is at least one)."""
        deadline = time.monotonic() + timeout
        out: list = []
        while True:
            data = self.conn.recv()
            if data:
                msgs = self.mav.parse_buffer(bytearray(data)) or []
                out.extend(m for m in msgs if m.get_type() != "BAD_DATA")
                continue
            if out:
                break
            left = deadline - time.monotonic()
            if left <= 0:
                break
            self.conn.select(left)
        self.rx_count += len(out)
        return out

    def wait_heartbeat(
        self,
        *,
        timeout: float,
        exclude_gcs: bool = True,
        system: int | None = None,
        component: int | None = None,
    ) -> mavlink2.MAVLink_heartbeat_message:
        """Wait for a HEARTBEAT from a vehicle (not a ground station), of ``system`` / ``component`` when given,
        and return it.

        Raises
        ------
        PeerTimeoutError
            When none arrives within ``timeout`` seconds (the message names the vehicles heard instead).
        TransportError
            With a signing key, when the vehicle's heartbeat is unsigned or signed with another key.
        """
        deadline = time.monotonic() + timeout
        next_beat = 0.0
        heard: set[tuple[int, int]] = set()
        while True:
            now = time.monotonic()
            left = deadline - now
            if left <= 0:
                raise PeerTimeoutError(_no_heartbeat(self.url, timeout, system, component, heard))
            if now >= next_beat and self._can_send():
                self.send_heartbeat()
                next_beat = now + 0.5
            for m in self.poll(min(left, 0.1)):
                if m.get_type() != "HEARTBEAT" or (exclude_gcs and m.type == mavlink2.MAV_TYPE_GCS):
                    continue
                source = (m.get_srcSystem(), m.get_srcComponent())
                if (system is not None and source[0] != system) or (component is not None and source[1] != component):
                    heard.add(source)
                    continue
                if self.signed and not m.get_signed():
                    raise TransportError(
                        f"vehicle {source[0]}/{source[1]} on {self.url} does "
                        "not sign with this key (its heartbeat is unsigned or signed with "
                        "another key)"
                    )
                return m

    def _can_send(self) -> bool:
        # a udpin link learns its peer from the first datagram; until then it has nobody to send to
        return not (getattr(self.conn, "udp_server", False) and getattr(self.conn, "last_address", None) is None)

    def send_heartbeat(self) -> None:
        """Send a ground-station HEARTBEAT (a vehicle on a ``udpin`` port learns our address from it)."""
        self.send(mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))

    def close(self) -> None:
        """Close the underlying device."""
        try:
            self.conn.close()
        except OSError:
            pass

    def __enter__(self) -> MavLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
