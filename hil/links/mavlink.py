"""The ``mavlink`` HIL transport: samples as DEBUG_FLOAT_ARRAY, commands as HIL_ACTUATOR_CONTROLS.

Plant → controller: ``DEBUG_FLOAT_ARRAY`` (name ``GL_SAMPLE``, ``array_id`` 1) with
``data = y[0..p-1], r[0..q-1]`` and ``time_usec = seq * round(Ts * 1e6)``.
Controller → plant: ``HIL_ACTUATOR_CONTROLS`` with the same ``time_usec`` (lockstep: the answer
names its sample), ``controls[0..m-1] = u`` and ``flags``: bits 0-15 are MAVLink's own (bit 0 its LOCKSTEP flag;
gainlink sets none of them), bits 16-31 the step's status flags (the one table, :mod:`gainlink.laws.flags`: the
same bits as the CAN status byte; RESET on the answer to a reset), bits 32-47 the saturation mask (bit 32+k: input k
clamped). That is wire format 4 (``wire=4`` on the node's ready line, AUTOPILOT_VERSION's
``middleware_sw_version``); a scheduled law's sample carries its external scheduling signals after ``r``.

Scenario table::

    [transport]
    kind = "mavlink"
    port = 14560                 # the controller listens on udpin:127.0.0.1:<port>
    # or, explicitly: url = "udpout:127.0.0.1:14560" (plant side), controller_url = "udpin:127.0.0.1:14560"
    busy_poll_us = 0             # optional: both ends poll without sleeping this long before blocking
                                 # (the firmware app gets --spin-us N); changes timing only, not the trace
    signing_key = "key.hex"      # optional: MAVLink 2 signing (gainlink mavlink keygen): samples are signed,
                                 # only signed commands count, the firmware app gets --signing-key

    # the Cortex-M4F image on its UART (scenario controller = "qemu"): QEMU serves the UART here
    url = "tcp:127.0.0.1:5760"

Framing is pymavlink's (MAVLink 2, ``common`` dialect) on a plain UDP socket, or on the TCP byte stream of
the image's UART (frames may then arrive split or several at once; bytes that are not a frame are skipped).
"""

from __future__ import annotations

import collections
import selectors
import socket
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gainlink.errors import TransportError
from gainlink.firmware.uart import tcp_endpoint
from gainlink.laws.flags import MAVLINK_FLAGS_SHIFT, MAVLINK_SAT_SHIFT
from pymavlink.dialects.v20 import common as mavlink2

from ..registry import take_keys
from .base import TRANSPORTS, Command, Transport

ARRAY_SAMPLE = 1
ARRAY_RESET = 2
ARRAY_IDLE = 3


def status_of(flags: int) -> int:
    """The status bits of a command's HIL_ACTUATOR_CONTROLS ``flags`` (bits 16-31: the one table's bits 0-15)."""
    return (flags >> MAVLINK_FLAGS_SHIFT) & 0xFFFF


def flags_of(status: int, sat: int) -> int:
    """The HIL_ACTUATOR_CONTROLS ``flags`` of a command's status bits and saturation mask (a node's side of
    :func:`status_of`): the status at bits 16-31, the saturation mask at bits 32-47, MAVLink's bits 0-15 clear."""
    return ((int(status) & 0xFFFF) << MAVLINK_FLAGS_SHIFT) | ((int(sat) & 0xFFFF) << MAVLINK_SAT_SHIFT)


DEFAULT_PORT = 14560
MAX_BUSY_POLL_US = 1_000_000


class _DebugFloatArray(mavlink2.MAVLink_debug_float_array_message):
    """DEBUG_FLOAT_ARRAY packed by pymavlink, with MAVLink 2's trailing-zero truncation done in C
    (``bytes.rstrip``) instead of pymavlink's per-byte Python loop over the 58-float array."""

    def pack(self, mav: mavlink2.MAVLink, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(self.time_usec, self.array_id, self._name_raw, *self.data)
        return self._pack(mav, self.crc_extra, payload.rstrip(b"\0") or payload[:1], force_mavlink1=force_mavlink1)


def _udp_endpoint(url: str, *, scheme: str) -> tuple[str, int]:
    parts = url.split(":")
    if len(parts) != 3 or parts[0] != scheme:
        raise TransportError(f"mavlink transport: expected {scheme}:HOST:PORT, got {url!r}")
    try:
        return parts[1], int(parts[2])
    except ValueError:
        raise TransportError(f"mavlink transport: bad port in {url!r}") from None


class MavlinkTransport(Transport):
    """Plant-side end of the MAVLink HIL link (UDP).

    Parameters
    ----------
    url : str
        Where the controller listens, as the plant sees it: ``udpout:HOST:PORT``, or ``tcp:HOST:PORT`` for
        the UART of the Cortex-M4F image in QEMU (a byte stream).
    controller_url : str
        The controller's own link argument: ``udpin:HOST:PORT`` (unused with ``tcp:``).
    n_inputs, n_outputs, n_refs : int
        m, p, q of the loop.
    ts : float
        Sample time (for ``time_usec``).
    system, component : int
        Our MAVLink ids.
    busy_poll_us : int
        While waiting for a command, read without blocking for up to this long before falling back
        to a blocking wait (0, the default: block at once). Also passed to the firmware app as
        ``--spin-us``. Lower latency for 100 % of a core while waiting.
    signing_key : Path, optional
        MAVLink 2 signing key file: every sample is signed and only correctly signed commands are taken
        (the firmware app gets ``--signing-key``; the Python reference node does not sign).
    """

    seq_modulo = 1 << 32

    def __init__(
        self,
        *,
        url: str,
        controller_url: str,
        n_inputs: int,
        n_outputs: int,
        n_refs: int,
        ts: float,
        system: int = 255,
        component: int = mavlink2.MAV_COMP_ID_MISSIONPLANNER,
        busy_poll_us: int = 0,
        signing_key: Any = None,
    ):
        if not 0 <= busy_poll_us <= MAX_BUSY_POLL_US:
            raise TransportError(f"mavlink transport: busy_poll_us must be 0..{MAX_BUSY_POLL_US}, not {busy_poll_us!r}")
        if n_outputs + n_refs > 58 or n_inputs > 16:
            raise TransportError("mavlink transport: at most 58 outputs+references and 16 inputs fit the messages")
        self.url = url
        self.controller_url = controller_url
        self.stream = url.startswith("tcp:")
        self.dest = tcp_endpoint(url) if self.stream else _udp_endpoint(url, scheme="udpout")
        self.m, self.p, self.q = n_inputs, n_outputs, n_refs
        self.ts_us = max(1, int(round(ts * 1e6)))
        self.busy_poll_us = int(busy_poll_us)
        self._busy_poll_ns = self.busy_poll_us * 1000
        self.mav = mavlink2.MAVLink(None, srcSystem=system, srcComponent=component)
        self.signing_key = signing_key
        self._key: bytes | None = None
        if signing_key is not None:
            from gainlink.mavlink.signing import SigningKeyError, enable, read_key

            try:
                self._key = read_key(signing_key)
                enable(self.mav, self._key, link_id=2)
            except SigningKeyError as exc:
                raise TransportError(f"transport: {exc}") from None
        # on the UART's byte stream the same object also parses (it keeps a partial frame between reads)
        self.mav.robust_parsing = self.stream
        self._pending: collections.deque[Command] = collections.deque()
        self._eof = False
        self.sock: socket.socket | None = None
        self._sel: selectors.BaseSelector | None = None
        self._pad = np.zeros(58, dtype=np.float32)
        self.stats = {"sent": 0, "received": 0, "foreign": 0}

    # -- lifecycle -----------------------------------------------------------------------------
    def open(self) -> None:
        if self.stream:
            self._open_stream()
            return
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind(("0.0.0.0" if self.dest[0] not in ("127.0.0.1", "localhost") else "127.0.0.1", 0))
            sock.connect(self.dest)
        except OSError as exc:
            raise TransportError(f"mavlink transport: cannot open {self.url}: {exc.strerror}") from None
        sock.setblocking(False)
        self.sock = sock
        self._sel = selectors.DefaultSelector()
        self._sel.register(sock, selectors.EVENT_READ)

    def _open_stream(self) -> None:
        try:
            sock = socket.create_connection(self.dest, timeout=5.0)
        except OSError as exc:
            raise TransportError(f"mavlink transport: cannot connect to {self.url}: {exc.strerror or exc}") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(None)
        self.sock = sock
        self._sel = selectors.DefaultSelector()
        self._sel.register(sock, selectors.EVENT_READ)

    def close(self) -> None:
        if self._sel is not None:
            self._sel.close()
            self._sel = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    # -- samples -------------------------------------------------------------------------------
    def _frame(self, *, array_id: int, name: bytes, seq: int, values: np.ndarray | None = None) -> bytes:
        data = self._pad.copy()
        if values is not None:
            data[: values.size] = values
        msg = _DebugFloatArray(seq * self.ts_us, name, array_id, data.tolist())
        return msg.pack(self.mav)

    def encode_sample(self, *, seq: int, y: np.ndarray, r: np.ndarray) -> list[Any]:
        values = np.concatenate([np.asarray(y, dtype=np.float32).ravel(), np.asarray(r, dtype=np.float32).ravel()])
        return [self._frame(array_id=ARRAY_SAMPLE, name=b"GL_SAMPLE", seq=seq % self.seq_modulo, values=values)]

    def encode_reset(self, *, seq: int) -> list[Any]:
        """The frame that resets the controller's state (answered with the RESET status flag)."""
        return [self._frame(array_id=ARRAY_RESET, name=b"GL_RESET", seq=seq % self.seq_modulo)]

    def encode_idle(self, *, seq: int) -> list[Any]:
        """The frame of a period without a measurement (the controller's watchdog counts it)."""
        return [self._frame(array_id=ARRAY_IDLE, name=b"GL_IDLE", seq=seq % self.seq_modulo)]

    def send_frames(self, frames: Sequence[Any]) -> None:
        if self.sock is None:
            raise TransportError("mavlink transport: not open")
        for f in frames:
            try:
                if self.stream:
                    self.sock.sendall(f)
                    self.stats["sent"] += 1
                    continue
                self.sock.send(f)
            except ConnectionRefusedError:
                pass  # nobody listening yet: like a lost datagram
            except OSError as exc:
                raise TransportError(f"mavlink transport: send failed: {exc.strerror}") from None
            self.stats["sent"] += 1

    def receive_command(self, *, timeout: float) -> Command | None:
        if self.sock is None:
            raise TransportError("mavlink transport: not open")
        if self._pending:
            return self._pending.popleft()
        deadline = time.monotonic() + timeout
        spin_ns = min(self._busy_poll_ns, int(timeout * 1e9))
        spin_until = time.perf_counter_ns() + spin_ns if spin_ns > 0 else 0
        while True:
            try:
                data = self.sock.recv(4096, socket.MSG_DONTWAIT)
            except (BlockingIOError, ConnectionRefusedError):
                if spin_until and time.perf_counter_ns() < spin_until:
                    continue  # busy poll: read again without sleeping
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._sel.select(left)
                continue
            except OSError as exc:
                raise TransportError(f"mavlink transport: receive failed: {exc.strerror}") from None
            if self.stream and not data:
                return self._closed(deadline)
            self._pending.extend(self._decode(data))
            if self._pending:
                return self._pending.popleft()

    def _closed(self, deadline: float) -> None:
        """The image closed the UART connection (QEMU stopped): no command; the bridge asks the peer why."""
        self._eof = True
        left = deadline - time.monotonic()
        if left > 0:
            time.sleep(min(left, 0.05))
        return None

    def _messages(self, data: bytes) -> list:
        if self.stream:
            return [m for m in self.mav.parse_buffer(bytearray(data)) or [] if m.get_type() != "BAD_DATA"]
        try:
            if len(data) > 2 and data[0] == 0xFD and len(data) == 12 + data[1] + (13 if data[2] & 1 else 0):
                return [self.mav.decode(bytearray(data))]  # one MAVLink 2 frame per datagram (signature checked)
            return self.mav.parse_buffer(bytearray(data)) or []
        except mavlink2.MAVError:
            return []

    def _decode(self, data: bytes) -> list[Command]:
        out = []
        for msg in self._messages(data):
            if msg.get_msgId() != mavlink2.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS:
                self.stats["foreign"] += 1
                continue
            self.stats["received"] += 1
            flags = int(msg.flags)
            u = np.asarray(msg.controls[: self.m], dtype=float)
            sat = np.array([(flags >> (MAVLINK_SAT_SHIFT + k)) & 1 for k in range(self.m)], dtype=bool)
            status = status_of(flags)  # the status flags, as the table numbers them
            seq = (int(msg.time_usec) // self.ts_us) % self.seq_modulo
            out.append(Command(seq=seq, u=u, saturated=sat, status=status, t_ns=time.perf_counter_ns(), wire=flags))
        return out

    def _not_uart(self, what: str) -> None:
        if self.stream:
            raise TransportError(
                f"mavlink transport: {self.url} is the UART of the Cortex-M4F image in QEMU; "
                f'it needs controller = "qemu", not {what}'
            )

    def controller_argv(self) -> list[str]:
        from gainlink.firmware.mavlink_app import signing_argv, spin_argv

        self._not_uart("the host firmware app")
        return ["--url", self.controller_url, *spin_argv(self.busy_poll_us), *signing_argv(self.signing_key)]

    def firmware_executable(self, artifact: Any) -> Any:
        """The firmware host executable that speaks this link (``gainlink_mavlink``, built on demand)."""
        from gainlink.firmware.mavlink_app import mavlink_executable

        self._not_uart("the host firmware app")
        return mavlink_executable(artifact)

    def reference_argv(self, artifact_path: Any) -> list[str]:
        """The Python reference node that speaks this link (``controller = "reference"``)."""
        import sys

        self._not_uart('controller = "reference"')
        if self.signing_key is not None:
            raise TransportError(
                'transport: signing_key needs controller = "firmware" (the reference node does not sign)'
            )
        return [
            sys.executable,
            "-m",
            "gainlink.hil.links.mavlink_node",
            str(artifact_path),
            "--url",
            self.controller_url,
        ]

    def qemu_serve(self) -> tuple[str, str, int, list[str]]:
        """How the Cortex-M4F image must serve this link: ``(protocol, host, port, options)``."""
        if not self.stream:
            raise TransportError(
                f'controller = "qemu" needs the image\'s UART as the link: url = "tcp:HOST:PORT", not {self.url!r}'
            )
        return "mavlink", self.dest[0], self.dest[1], []

    @property
    def signing_key_bytes(self) -> bytes | None:
        """The 32-byte signing key of this link, if it is signed (the image gets it in its flash)."""
        return self._key

    @property
    def config(self) -> dict:
        """The transport's configuration as a scenario table."""
        cfg = {"kind": "mavlink", "url": self.url, "controller_url": self.controller_url}
        if self.busy_poll_us:
            cfg["busy_poll_us"] = self.busy_poll_us
        if self.signing_key is not None:
            cfg["signing_key"] = str(self.signing_key)
        return cfg

    def _refused(self) -> int:
        """Messages refused for a missing or wrong signature (0 on an unsigned link)."""
        return self.mav.signing.reject_count + self.mav.signing.badsig_count if self.signing_key is not None else 0

    def silence_hint(self) -> str:
        heard, refused = [], self._refused()
        if refused:
            heard.append(f"{refused} message(s) refused for a missing or wrong signature (not the link's key?)")
        if self.stats["foreign"]:
            heard.append(f"{self.stats['foreign']} message(s) that are not commands")
        other = " and ".join(heard) if heard else "nothing else"
        return f"; in the run the link got {self.stats['received']} command(s) and {other}"

    def describe(self) -> dict:
        out = {
            "kind": "mavlink",
            "url": self.url,
            "controller_url": self.controller_url,
            "messages": "DEBUG_FLOAT_ARRAY -> HIL_ACTUATOR_CONTROLS",
            "ts_us": self.ts_us,
            "busy_poll_us": self.busy_poll_us,
            "signed": self.signing_key is not None,
            "datagrams_sent": self.stats["sent"],
            "commands_received": self.stats["received"],
            "foreign_messages": self.stats["foreign"],
            "unsigned_or_bad_answers": self._refused(),
        }
        if self.stream:
            out["uart"] = True
            out["sample_bytes"] = len(self.encode_sample(seq=1, y=np.zeros(self.p), r=np.zeros(self.q))[0])
        return out


@TRANSPORTS.register("mavlink")
def _from_config(config: Mapping[str, Any], *, artifact: Any, **_: Any) -> MavlinkTransport:
    cfg = take_keys(
        config,
        allowed={"kind", "port", "host", "url", "controller_url", "busy_poll_us", "signing_key"},
        where="transport",
        error=TransportError,
    )
    host = str(cfg.get("host", "127.0.0.1"))
    port = cfg.get("port", DEFAULT_PORT)
    if not isinstance(port, int) or not 0 < port < 65536:
        raise TransportError(f"transport: port must be an integer 1..65535, not {port!r}")
    busy = cfg.get("busy_poll_us", 0)
    if isinstance(busy, bool) or not isinstance(busy, int) or not 0 <= busy <= MAX_BUSY_POLL_US:
        raise TransportError(
            f"transport: busy_poll_us must be an integer 0..{MAX_BUSY_POLL_US} (microseconds), not {busy!r}"
        )
    url = str(cfg.get("url", f"udpout:{host}:{port}"))
    if url.startswith("tcp:"):
        if "controller_url" in cfg or "port" in cfg:
            raise TransportError('transport: url = "tcp:..." (the image\'s UART) takes no port or controller_url')
        controller_url = ""
    else:
        controller_url = str(cfg.get("controller_url", f"udpin:{host}:{_udp_endpoint(url, scheme='udpout')[1]}"))
    key = cfg.get("signing_key")
    if key is not None and not isinstance(key, str):
        raise TransportError(f"transport: signing_key must be a key file path, not {key!r}")
    return MavlinkTransport(
        url=url,
        controller_url=controller_url,
        n_inputs=artifact.m,
        n_outputs=artifact.p,
        n_refs=artifact.q,
        ts=float(artifact.Ts),
        busy_poll_us=busy,
        signing_key=key,
    )
