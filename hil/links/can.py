"""CAN transport: python-can bus built from configuration only, frames laid out by :mod:`can_layout`.

``can.Bus(**config)`` takes the scenario's python-can table unchanged (``interface``, ``channel``,
``fd``, ``hop_limit``, ...) except gainlink's own keys: ``kind``, ``base_id`` (first CAN id),
``busy_poll_us`` (poll without sleeping for this long before blocking, on both ends: lower latency for
100 % of a core while waiting; default 0), ``reply_port`` (udp_multicast only: the controller answers on this port
of the group, the samples travel on ``port``, so neither end reads back its own frames; see
:func:`open_link_buses`), ``encoding`` (``"float32"``, the default, or ``"int16"``:
scaled integers, ``physical = raw * factor + offset``) and ``ranges`` (with int16, ``{ signal = [min,
max], ... }`` for every output and reference, by the artifact's signal names; inputs default to the
artifact's ``u_min``/``u_max``). With int16, values beyond their range saturate to its ends; the
plant side counts them (``encoding_clipped`` in the report's transport description) and warns once.
The same code runs on ``udp_multicast`` (no kernel CAN) and ``socketcan``/``vcan0``.

``interface = "slcan"`` talks to a USB-CAN adapter's serial protocol (Lawicel); with ``channel =
"socket://HOST:PORT"`` and the scenario's ``controller = "qemu"`` that is the Cortex-M4F image's UART in
QEMU, which speaks slcan itself. slcan carries classic frames only (no ``fd``); python-can's two-second
pause after opening the port is skipped unless ``sleep_after_open`` says otherwise.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gainlink.errors import TransportError
from gainlink.fileio import parse_toml
from gainlink.laws.flags import can_header
from gainlink.shipping.can_layout import CanLayout, FrameSpec, dequantise, layout_for, quantise

from .base import TRANSPORTS, Command, Transport

log = logging.getLogger(__name__)

GAINLINK_KEYS = {"kind", "base_id", "busy_poll_us", "reply_port", "encoding", "ranges"}
FIRMWARE_INTERFACES = {"udp_multicast", "socketcan"}


def _multicast_hint(exc: BaseException, config: Mapping[str, Any]) -> str:
    """A how-to-fix hint when udp_multicast fails for want of a multicast route (loopback-only machines)."""
    cause = exc if isinstance(exc, OSError) else exc.__cause__  # python-can wraps the socket error
    if (
        config.get("interface") == "udp_multicast"
        and isinstance(cause, OSError)
        and cause.errno in (errno.ENETUNREACH, errno.ENODEV, errno.EADDRNOTAVAIL)
    ):
        return (
            f" ({cause.strerror}: no multicast route; on a loopback-only machine run "
            "'ip link set lo up multicast on; ip route add 224.0.0.0/4 dev lo')"
        )
    return ""


def bus_kwargs(config: Mapping[str, Any]) -> dict:
    """The python-can keyword arguments of a transport table (gainlink's own keys removed)."""
    return {k: v for k, v in config.items() if k not in GAINLINK_KEYS}


def open_bus(config: Mapping[str, Any]) -> Any:
    """``can.Bus(**config)``; any failure becomes one :class:`TransportError` line."""
    import can

    kwargs = bus_kwargs(config)
    if "interface" not in kwargs:
        raise TransportError("CAN transport: the configuration needs interface (e.g. udp_multicast, socketcan)")
    try:
        bus = can.Bus(**kwargs)
    except Exception as exc:  # python-can raises CanError, OSError, ValueError, ImportError by backend
        where = ", ".join(f"{k}={kwargs[k]}" for k in ("interface", "channel") if k in kwargs)
        raise TransportError(f"cannot open CAN bus ({where}): {exc}{_multicast_hint(exc, kwargs)}") from None
    if kwargs["interface"] == "udp_multicast":
        _enlarge_receive_buffer(bus)
    return bus


def reply_port(config: Mapping[str, Any]) -> int | None:
    """The port the controller answers on (``reply_port``), or None when both directions share ``port``.

    Raises
    ------
    TransportError
        ``reply_port`` on another interface than udp_multicast, not a port, or ``port`` itself (one line).
    """
    value = config.get("reply_port")
    if value is None:
        return None
    if config.get("interface") != "udp_multicast":
        raise TransportError(
            f'CAN transport: reply_port is for interface = "udp_multicast" (not {config.get("interface")}): '
            "other interfaces do not echo a member's own frames"
        )
    port = config.get("port", 43113)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 65535 or value == port:
        raise TransportError(f"CAN transport: reply_port must be a UDP port 1..65535 other than port {port}")
    return value


def open_link_buses(config: Mapping[str, Any], *, controller: bool = False) -> tuple[Any, Any]:
    """``(receive bus, send bus)`` of one end of the link: the plant's, or the ``controller``'s.

    One bus for both, unless the configuration has a ``reply_port``: on udp_multicast every member of a group
    receives every datagram sent to its port, its own included, and python-can unpacks each one (as much work again
    as the frames the end wants). With a ``reply_port`` the samples travel on ``port`` and the commands on
    ``reply_port``; each end receives on the port it listens to, and sends through a second bus on the other port
    whose reception is switched off (:func:`_deaf`), so nobody reads back its own frames. A member listening on
    ``port`` alone (a logger) then hears the samples only.
    """
    reply = reply_port(config)
    if reply is None:
        bus = open_bus(config)
        return bus, bus
    sample, command = dict(config), {**config, "port": reply}
    listen, speak = (sample, command) if controller else (command, sample)
    rx = open_bus(listen)
    try:
        tx = open_bus(speak)
    except TransportError:
        rx.shutdown()
        raise
    _deaf(tx, group=str(speak.get("channel", "")))
    return rx, tx


def _deaf(bus: Any, *, group: str) -> None:
    """Switch off a send-only udp_multicast bus's reception (IPv4): it leaves the group and stops receiving the
    groups other sockets joined (``IP_MULTICAST_ALL`` off), so the kernel queues none of the frames it sends. It
    can still send to the group. Through the bus's public ``fileno()``; an IPv6 group keeps its reception (its
    queue fills and the kernel drops the rest, unread)."""
    import socket
    import struct

    try:
        member = socket.inet_aton(group) + struct.pack("@I", socket.INADDR_ANY)
    except OSError:
        return  # not an IPv4 group
    with socket.socket(fileno=os.dup(bus.fileno())) as sock:
        try:
            sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_DROP_MEMBERSHIP, member)
        except OSError as exc:  # not Linux: the bus keeps hearing its own frames, unread
            log.debug("udp_multicast: a send-only bus keeps its reception: %s", exc)


IP_MULTICAST_ALL = 49  # linux/in.h; Python's socket module does not name it


RECEIVE_BUFFER = 4 << 20


def _enlarge_receive_buffer(bus: Any) -> None:
    """Give a udp_multicast bus's socket a 4 MiB receive buffer (beyond rmem_max when permitted, as the firmware
    does): every member gets every datagram on the group, and a burst of foreign traffic must not push out the
    commands of a run. Through the bus's public ``fileno()``; a refusal leaves the default."""
    import socket

    fd = bus.fileno()
    if fd < 0:
        return
    with socket.socket(fileno=os.dup(fd)) as sock:
        for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
            if option is None:
                continue
            try:
                sock.setsockopt(socket.SOL_SOCKET, option, RECEIVE_BUFFER)
                return
            except OSError:
                continue


def layout_from_config(config: Mapping[str, Any], *, artifact: Any) -> CanLayout:
    """The layout a transport table asks for (``fd``, ``base_id``, ``encoding``, ``ranges``).

    Raises
    ------
    TransportError
        A bad ``base_id``, ``encoding`` or ``ranges`` (one line naming it).
    """
    base = config.get("base_id", 0x100)
    if isinstance(base, str):
        try:
            base = int(base, 0)
        except ValueError:
            raise TransportError(f"CAN transport: base_id {base!r} is not an integer") from None
    return layout_for(
        artifact,
        fd=bool(config.get("fd", False)),
        base_id=int(base),
        encoding=config.get("encoding", "float32"),
        ranges=config.get("ranges"),
    )


class FrameCodec:
    """Encode/decode one side's frames with structs derived from the layout (checked against cantools in tests).

    With ``int16`` the per-value factor and offset are those of the layout's :class:`FrameSpec` (the
    numbers the DBC carries). ``clipped`` counts values this codec encoded beyond their range.
    """

    def __init__(self, specs: Sequence[FrameSpec], *, fd: bool) -> None:
        import can

        self._Message = can.Message
        self.fd = fd
        self.header = can_header(fd)
        self.specs = tuple(specs)
        self.by_id = {s.arbitration_id: s for s in specs}
        self.structs = {s.arbitration_id: s.struct for s in specs}
        self.size = sum(len(s.signals) for s in specs)
        self.int16 = any(s.encoding == "int16" for s in specs)
        self.names = [n for s in specs for n in s.signals]
        self.clipped = 0
        if self.int16:
            self.factors = np.array([f for s in specs for f in s.factors])
            self.offsets = np.array([o for s in specs for o in s.offsets])
            self._scale = {s.arbitration_id: (np.array(s.factors), np.array(s.offsets)) for s in specs}

    def quantise(self, values: np.ndarray) -> np.ndarray:
        """Raw int16 values of a whole vector; counts (and warns once about) values beyond their range."""
        raw, clipped = quantise(values, self.factors, self.offsets)
        if clipped.any():
            if self.clipped == 0:
                i = int(np.flatnonzero(clipped)[0])
                lo, hi = self.offsets[i] - 32767 * self.factors[i], self.offsets[i] + 32767 * self.factors[i]
                log.warning(
                    "CAN int16: %s = %g is outside its range [%g, %g] and was sent saturated; further "
                    "clipping is counted (encoding_clipped), not logged",
                    self.names[i],
                    float(np.asarray(values)[i]),
                    lo,
                    hi,
                )
            self.clipped += int(clipped.sum())
        return raw

    def encode(self, *, seq: int, values: np.ndarray, status: int = 0, sat: np.ndarray | None = None) -> list[Any]:
        frames = []
        seq &= 0xFFFF
        if self.int16:
            vals = self.quantise(np.asarray(values, dtype=float)).tolist()
        else:  # Python floats (a float32 field packs them as the C reads them)
            vals = values.tolist() if isinstance(values, np.ndarray) else [float(v) for v in values]
        # wire format 4: the header as one integer (gainlink.shipping.flags.CanHeader), each frame's saturation bits
        # (fewer than the header's sat_bits: a frame has one per value) added to what every frame of the step shares
        head, sat_at = self.header.pack(seq, status, 0), self.header.sat_start
        for s in self.specs:
            k = len(s.signals)
            bits = 0
            if sat is not None:
                for i in range(k):
                    if sat[s.first + i]:
                        bits |= 1 << i
            data = self.structs[s.arbitration_id].pack(head | bits << sat_at, *vals[s.first : s.first + k])
            frames.append(
                self._Message(
                    arbitration_id=s.arbitration_id, is_extended_id=False, data=data, is_fd=self.fd, check=False
                )
            )
        return frames

    def decode(self, arbitration_id: int, data: bytes) -> tuple[int, int, int, np.ndarray] | None:
        """``(seq, status, sat bits, physical values)`` of one frame of this side, ``None`` if too short."""
        st = self.structs[arbitration_id]
        if len(data) < st.size:
            log.debug("short frame id %#x (%d bytes)", arbitration_id, len(data))
            return None
        head, *vals = st.unpack_from(data)
        seq, status, bits = self.header.unpack(head)
        if self.int16:
            factors, offsets = self._scale[arbitration_id]
            return seq, status, bits, dequantise(np.array(vals), factors, offsets)
        return seq, status, bits, np.array(vals)


class Assembler:
    """Collects the frames of one side into complete (seq, values, status, sat) records."""

    def __init__(self, codec: FrameCodec) -> None:
        self.codec = codec
        self.partial: dict[int, list] = {}
        self.single = len(codec.specs) == 1
        self._shifts = np.arange(codec.size)
        self._sat_seen: dict[int, np.ndarray] = {}  # a frame's saturation bits as a mask, for the first patterns

    def _sat_mask(self, bits: int) -> np.ndarray:
        """The saturation bits of a whole vector as booleans (looked up: a run sees few patterns; at most 256 kept,
        so that hostile traffic cannot grow the table)."""
        mask = self._sat_seen.get(bits)
        if mask is None:
            mask = (bits >> self._shifts) & 1 == 1
            if len(self._sat_seen) < 256:
                self._sat_seen[bits] = mask
        return mask.copy()

    def feed(self, msg: Any) -> tuple[int, np.ndarray, int, np.ndarray] | None:
        spec = self.codec.by_id.get(msg.arbitration_id)
        if spec is None or msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            return None
        got = self.codec.decode(msg.arbitration_id, msg.data)
        if got is None:
            return None
        seq, status, bits, vals = got
        if self.single:  # one frame carries the whole vector (CAN FD, or a single value)
            return seq, vals, status, self._sat_mask(bits)
        rec = self.partial.get(seq)
        if rec is None:
            if len(self.partial) > 32:
                self.partial.clear()
            rec = [np.empty(self.codec.size), np.zeros(self.codec.size, dtype=bool), 0, set()]
            self.partial[seq] = rec
        rec[0][spec.first : spec.first + len(vals)] = vals
        for i in range(len(vals)):
            rec[1][spec.first + i] = bool(bits >> i & 1)
        rec[2] |= status
        rec[3].add(msg.arbitration_id)
        if len(rec[3]) == len(self.codec.specs):
            del self.partial[seq]
            return seq, rec[0], rec[2], rec[1]
        return None


class CanTransport(Transport):
    """Plant side of the CAN link.

    Parameters
    ----------
    config : mapping
        python-can configuration (``interface``, ``channel``, ``fd``, ...) plus gainlink's optional
        ``base_id``, ``busy_poll_us``, ``encoding`` and ``ranges`` (see the module docstring).
    artifact : gainlink.shipping.artifact.Artifact
        Gives the layout (sizes, signal names, input limits).
    """

    def __init__(self, config: Mapping[str, Any], *, artifact: Any) -> None:
        self.config = dict(config)
        self.config.pop("kind", None)
        self.fd = bool(self.config.get("fd", False))
        self.slcan = self.config.get("interface") == "slcan"
        if self.slcan:
            if self.fd:
                raise TransportError(
                    "CAN transport: slcan carries classic frames only (remove fd = true; the "
                    "int16 encoding fits two values per frame)"
                )
            self.config.setdefault("sleep_after_open", 0)
        self.layout: CanLayout = layout_from_config(self.config, artifact=artifact)
        self.tx = FrameCodec(self.layout.measurement, fd=self.fd)
        self.rx = Assembler(FrameCodec(self.layout.command, fd=self.fd))
        reply_port(self.config)  # a bad reply_port is refused before anything opens
        self.bus: Any = None  # the bus the commands come on
        self._tx: Any = None  # the bus the samples go out on: the same one without a reply_port
        self.m = artifact.m
        self.busy_poll_ns = int(float(self.config.get("busy_poll_us", 0)) * 1000)
        from can import CanOperationError

        self._can_error = CanOperationError
        self.frames_sent = 0
        self.frames_refused = 0  # datagrams python-can could not unpack (hostile or corrupt traffic on the bus)
        self._last_done: int | None = None  # the last sample the node steps on (steps_on)

    def open(self) -> None:
        if self.bus is None:
            self.bus, self._tx = open_link_buses(self.config)

    def close(self) -> None:
        """Shut the link's buses down. A Ctrl-C that lands in the middle (at the start of python-can's ``shutdown``,
        before it marks the bus shut) is raised once the buses still held are shut: dropped half-shut, a bus's
        finaliser logged "was not properly shut down" above the interrupted command's one line."""
        try:
            self._shut_buses()
        except KeyboardInterrupt:
            self._shut_buses()  # python-can's shutdown may be called again: a bus already shut returns at once
            raise

    def _shut_buses(self) -> None:
        """Shut the send bus, then the receive bus, each let go once its ``shutdown`` has returned or raised an
        error (not an interrupt)."""
        if self._tx is not None and self._tx is not self.bus:
            self._tx.shutdown()
        self._tx = None
        if self.bus is None:
            return
        try:
            self.bus.shutdown()
        except Exception as exc:
            if not self.slcan:
                self.bus = None
                raise
            # slcan's shutdown writes "C" to the adapter first; when the adapter (the image in QEMU) is
            # already gone that write fails and python-can leaves the port open: close it here
            log.debug("slcan: closing a link whose other end is gone: %s", exc)
            port = getattr(self.bus, "serialPortOrig", None)
            if port is not None:
                port.close()
        self.bus = None

    def encode_sample(self, *, seq: int, y: np.ndarray, r: np.ndarray) -> list[Any]:
        return self.tx.encode(seq=seq, values=[*np.asarray(y).tolist(), *np.asarray(r).tolist()])

    def steps_on(self, seq: int) -> bool:
        """The CAN node answers a sample once: a duplicate or a stale one (its 16-bit ``seq`` not ahead of the last
        answered) is skipped."""
        if self._last_done is not None:
            ahead = (seq - self._last_done) & 0xFFFF
            if ahead == 0 or ahead >= 0x8000:
                return False
        self._last_done = seq
        return True

    def received_sample(self, *, y: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the firmware decodes from this sample (float32, after int16 quantisation), as float64.

        For a shadow law that should see exactly the controller's inputs. Does not count clipping.
        """
        v = np.concatenate([y, r]).astype(np.float64)
        if self.tx.int16:
            raw, _ = quantise(v, self.tx.factors, self.tx.offsets)
            v = dequantise(raw, self.tx.factors, self.tx.offsets)
        v = v.astype(np.float32).astype(np.float64)
        return v[: len(y)], v[len(y) :]

    def send_frames(self, frames: Sequence[Any]) -> None:
        bus = self._tx
        try:
            for f in frames:
                bus.send(f)
                self.frames_sent += 1
        except Exception as exc:
            raise TransportError(f"CAN send failed: {exc}{_multicast_hint(exc, self.config)}") from None

    def receive_command(self, *, timeout: float) -> Command | None:
        bus = self.bus
        deadline = time.perf_counter() + timeout
        spin_until = time.perf_counter_ns() + self.busy_poll_ns
        while True:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return None
            try:
                if self.busy_poll_ns and time.perf_counter_ns() < spin_until:
                    msg = bus.recv(0.0)
                    if msg is None:
                        continue
                else:
                    msg = bus.recv(remaining)
            except Exception as exc:
                if self.slcan and isinstance(exc.__cause__ or exc, OSError):
                    # the serial link went away (e.g. QEMU stopped): no command; the bridge asks the peer why
                    time.sleep(min(max(remaining, 0.0), 0.05))
                    return None
                if not isinstance(exc, self._can_error) or isinstance(exc.__cause__, OSError) or exc.__cause__ is None:
                    raise TransportError(f"CAN receive failed: {exc}") from None
                self.frames_refused += 1  # a datagram that is no CAN frame: anyone can send to the group
                continue
            if msg is None:
                return None
            done = self.rx.feed(msg)
            if done is not None:
                seq, u, status, sat = done
                return Command(seq=seq, u=u, saturated=sat, status=status, t_ns=time.perf_counter_ns())

    def controller_argv(self) -> list[str]:
        return firmware_can_argv(self.config, layout=self.layout)

    def qemu_serve(self) -> tuple[str, str, int, list[str]]:
        """How the Cortex-M4F image must serve this link: ``(protocol, host, port, options)``."""
        from gainlink.firmware.uart import tcp_endpoint

        if not self.slcan:
            raise TransportError(
                f'controller = "qemu" speaks CAN through slcan on the image\'s UART: use '
                f'interface = "slcan", channel = "socket://HOST:PORT" (not {self.config.get("interface")})'
            )
        host, port = tcp_endpoint(str(self.config.get("channel", "")), scheme="socket")
        return "slcan", host, port, slcan_image_options(self.layout)

    def describe(self) -> dict:
        out = {
            "kind": "can",
            "config": {k: v for k, v in self.config.items()},
            "fd": self.fd,
            "base_id": self.layout.base_id,
            "frames_per_sample": len(self.layout.measurement),
            "frames_per_command": len(self.layout.command),
            "encoding": self.layout.encoding,
            "frames_sent": self.frames_sent,
            "frames_refused": self.frames_refused,
        }
        if self.tx.int16:
            out["encoding_clipped"] = self.tx.clipped  # measurement values sent saturated to their range
        return out


def _scale_arg(specs: Sequence[FrameSpec]) -> str:
    """``factor,offset;factor,offset;...`` of every value, floats as round-trip reprs (strtod reads them exactly)."""
    return ";".join(f"{f!r},{o!r}" for f, o in _value_scales(specs))


def firmware_can_argv(config: Mapping[str, Any], *, layout: CanLayout) -> list[str]:
    """Arguments for the firmware CAN app (``gainlink_can``) equivalent to a python-can configuration.

    With an int16 layout: ``--encoding int16 --scale-measurement F,O;... --scale-command F,O;...``,
    the factor and offset of every value (``y`` then ``r``; ``u``) taken from the layout's frames.
    """
    interface = config.get("interface")
    if interface not in FIRMWARE_INTERFACES:
        raise TransportError(
            f"the firmware CAN app speaks {' and '.join(sorted(FIRMWARE_INTERFACES))}, not interface={interface}"
        )
    argv = ["--base-id", str(layout.base_id)]
    if layout.fd:
        argv.append("--fd")
    if layout.encoding == "int16":
        argv += [
            "--encoding",
            "int16",
            "--scale-measurement",
            _scale_arg(layout.measurement),
            "--scale-command",
            _scale_arg(layout.command),
        ]
    spin = int(float(config.get("busy_poll_us", 0)))
    if spin > 0:
        argv += ["--spin-us", str(spin)]
    if interface == "socketcan":
        argv += ["--backend", "socketcan", "--channel", str(config.get("channel", "can0"))]
    else:
        argv += [
            "--backend",
            "udp",
            "--channel",
            str(config.get("channel", "239.74.163.2")),
            "--port",
            str(int(config.get("port", 43113))),
            "--hop-limit",
            str(int(config.get("hop_limit", 1))),
        ]
        reply = reply_port(config)
        if reply is not None:
            argv += ["--reply-port", str(reply)]
    return argv


def slcan_image_options(layout: CanLayout) -> list[str]:
    """The Cortex-M4F image's ``serve slcan`` options for a layout (see ``firmware/ports/cortex-m/serve.h``).

    With int16 the factor and offset of every value travel as the bits of their doubles, the same numbers
    the DBC and the host app's ``--scale-*`` carry.
    """
    from gainlink.firmware.uart import scale_option

    opts = [f"base={layout.base_id}", f"encoding={layout.encoding}"]
    if layout.encoding == "int16":
        opts += [
            f"meas={scale_option(_value_scales(layout.measurement))}",
            f"cmd={scale_option(_value_scales(layout.command))}",
        ]
    return opts


def _value_scales(specs: Sequence[FrameSpec]) -> list[tuple[float, float]]:
    """``(factor, offset)`` of every value carried by ``specs``, in order."""
    return [(f, o) for s in specs for f, o in zip(s.factors, s.offsets)]


def config_from_text(text: str, *, source: str) -> dict:
    """A python-can configuration from JSON or TOML text (for ``--can CONFIG``)."""
    text = text.strip()
    if text.startswith("{"):
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise TransportError(f"CAN configuration {source} is not valid JSON ({exc})") from None
    else:
        data = parse_toml(text, what=f"CAN configuration {source}", error=TransportError)
    if "transport" in data and isinstance(data["transport"], dict):
        data = data["transport"]
    if not isinstance(data, dict) or "interface" not in data:
        raise TransportError(f"CAN configuration {source} needs an interface key")
    return data


@TRANSPORTS.register("can")
def _can_factory(config: Mapping[str, Any], *, artifact: Any, **_context: Any) -> Transport:
    return CanTransport(config, artifact=artifact)
