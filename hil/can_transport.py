"""CAN transport: python-can bus built from configuration only, frames laid out by :mod:`can_layout`.

``can.Bus(**config)`` takes the scenario's python-can table unchanged (``interface``, ``channel``,
``fd``, ``hop_limit``, ...) except gainlink's own keys: ``kind``, ``base_id`` (first CAN id) and
``busy_poll_us`` (poll without sleeping for this long before blocking, on both ends: lower latency for
100 % of a core while waiting; default 0). The same code runs
on ``udp_multicast`` (no kernel CAN) and ``socketcan``/``vcan0``.
"""

from __future__ import annotations

import errno
import json
import logging
import time
from typing import Any, Mapping, Sequence

import numpy as np

from gainlink.errors import TransportError

from .can_layout import CanLayout, FrameSpec, layout_for
from .transport import TRANSPORTS, Command, Transport

log = logging.getLogger(__name__)

GAINLINK_KEYS = {"kind", "base_id", "busy_poll_us"}
FIRMWARE_INTERFACES = {"udp_multicast", "socketcan"}


def _multicast_hint(exc: BaseException, config: Mapping[str, Any]) -> str:
    """A how-to-fix hint when udp_multicast fails for want of a multicast route (loopback-only machines)."""
    cause = exc if isinstance(exc, OSError) else exc.__cause__  # python-can wraps the socket error
    if config.get("interface") == "udp_multicast" and isinstance(cause, OSError) and \
            cause.errno in (errno.ENETUNREACH, errno.ENODEV, errno.EADDRNOTAVAIL):
        return (f" ({cause.strerror}: no multicast route; on a loopback-only machine run "
                "'ip link set lo up multicast on; ip route add 224.0.0.0/4 dev lo')")
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
        return can.Bus(**kwargs)
    except Exception as exc:  # python-can raises CanError, OSError, ValueError, ImportError by backend
        where = ", ".join(f"{k}={kwargs[k]}" for k in ("interface", "channel") if k in kwargs)
        raise TransportError(f"cannot open CAN bus ({where}): {exc}{_multicast_hint(exc, kwargs)}") from None


class FrameCodec:
    """Encode/decode one side's frames with structs derived from the layout (checked against cantools in tests)."""

    def __init__(self, specs: Sequence[FrameSpec], *, fd: bool) -> None:
        import can

        self._Message = can.Message
        self.fd = fd
        self.specs = tuple(specs)
        self.by_id = {s.arbitration_id: s for s in specs}
        self.structs = {s.arbitration_id: s.struct for s in specs}
        self.size = sum(len(s.signals) for s in specs)

    def encode(self, *, seq: int, values: np.ndarray, status: int = 0, sat: np.ndarray | None = None) -> list[Any]:
        frames = []
        seq &= 0xFFFF
        vals = [float(v) for v in values]
        for s in self.specs:
            k = len(s.signals)
            bits = 0
            if sat is not None:
                for i in range(k):
                    if sat[s.first + i]:
                        bits |= 1 << i
            data = self.structs[s.arbitration_id].pack(seq, status, bits, *vals[s.first:s.first + k])
            frames.append(self._Message(arbitration_id=s.arbitration_id, is_extended_id=False, data=data,
                                        is_fd=self.fd, check=False))
        return frames


class Assembler:
    """Collects the frames of one side into complete (seq, values, status, sat) records."""

    def __init__(self, codec: FrameCodec) -> None:
        self.codec = codec
        self.partial: dict[int, list] = {}
        self.single = len(codec.specs) == 1
        k = codec.size
        self._bits = [np.array([(b >> i) & 1 for i in range(k)], dtype=bool) for b in range(1 << min(k, 8))]

    def feed(self, msg: Any) -> tuple[int, np.ndarray, int, np.ndarray] | None:
        spec = self.codec.by_id.get(msg.arbitration_id)
        if spec is None or msg.is_extended_id:
            return None
        st = self.codec.structs[msg.arbitration_id]
        if len(msg.data) < st.size:
            log.debug("short frame id %#x (%d bytes)", msg.arbitration_id, len(msg.data))
            return None
        seq, status, bits, *vals = st.unpack_from(msg.data)
        if self.single:  # one frame carries the whole vector (CAN FD, or a single value)
            return seq, np.array(vals), status, self._bits[bits].copy()
        rec = self.partial.get(seq)
        if rec is None:
            if len(self.partial) > 32:
                self.partial.clear()
            rec = [np.empty(self.codec.size), np.zeros(self.codec.size, dtype=bool), 0, set()]
            self.partial[seq] = rec
        rec[0][spec.first:spec.first + len(vals)] = vals
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
        python-can configuration (``interface``, ``channel``, ``fd``, ...) plus optional ``base_id``.
    artifact : gainlink.artifact.Artifact
        Gives the layout (sizes and signal names).
    """

    def __init__(self, config: Mapping[str, Any], *, artifact: Any) -> None:
        self.config = dict(config)
        self.config.pop("kind", None)
        base = self.config.get("base_id", 0x100)
        if isinstance(base, str):
            try:
                base = int(base, 0)
            except ValueError:
                raise TransportError(f"CAN transport: base_id {base!r} is not an integer") from None
        self.fd = bool(self.config.get("fd", False))
        self.layout: CanLayout = layout_for(artifact, fd=self.fd, base_id=int(base))
        self.tx = FrameCodec(self.layout.measurement, fd=self.fd)
        self.rx = Assembler(FrameCodec(self.layout.command, fd=self.fd))
        self.bus: Any = None
        self.m = artifact.m
        self.busy_poll_ns = int(float(self.config.get("busy_poll_us", 0)) * 1000)

    def open(self) -> None:
        if self.bus is None:
            self.bus = open_bus(self.config)

    def close(self) -> None:
        if self.bus is not None:
            try:
                self.bus.shutdown()
            finally:
                self.bus = None

    def encode_sample(self, *, seq: int, y: np.ndarray, r: np.ndarray) -> list[Any]:
        return self.tx.encode(seq=seq, values=np.concatenate([y, r]))

    def send_frames(self, frames: Sequence[Any]) -> None:
        bus = self.bus
        try:
            for f in frames:
                bus.send(f)
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
                raise TransportError(f"CAN receive failed: {exc}") from None
            if msg is None:
                return None
            done = self.rx.feed(msg)
            if done is not None:
                seq, u, status, sat = done
                return Command(seq=seq, u=u, saturated=sat, status=status, t_ns=time.perf_counter_ns())

    def controller_argv(self) -> list[str]:
        return firmware_can_argv(self.config, layout=self.layout)

    def describe(self) -> dict:
        return {"kind": "can", "config": {k: v for k, v in self.config.items()}, "fd": self.fd,
                "base_id": self.layout.base_id, "frames_per_sample": len(self.layout.measurement),
                "frames_per_command": len(self.layout.command)}


def firmware_can_argv(config: Mapping[str, Any], *, layout: CanLayout) -> list[str]:
    """Arguments for the firmware CAN app (``gainlink_can``) equivalent to a python-can configuration."""
    interface = config.get("interface")
    if interface not in FIRMWARE_INTERFACES:
        raise TransportError(f"the firmware CAN app speaks {' and '.join(sorted(FIRMWARE_INTERFACES))}, "
                             f"not interface={interface}")
    argv = ["--base-id", str(layout.base_id)]
    if layout.fd:
        argv.append("--fd")
    spin = int(float(config.get("busy_poll_us", 0)))
    if spin > 0:
        argv += ["--spin-us", str(spin)]
    if interface == "socketcan":
        argv += ["--backend", "socketcan", "--channel", str(config.get("channel", "can0"))]
    else:
        argv += ["--backend", "udp", "--channel", str(config.get("channel", "239.74.163.2")),
                 "--port", str(int(config.get("port", 43113))), "--hop-limit", str(int(config.get("hop_limit", 1)))]
    return argv


def config_from_text(text: str, *, source: str) -> dict:
    """A python-can configuration from JSON or TOML text (for ``--can CONFIG``)."""
    import tomllib

    text = text.strip()
    try:
        data = json.loads(text) if text.startswith("{") else tomllib.loads(text)
    except (ValueError, tomllib.TOMLDecodeError) as exc:
        raise TransportError(f"CAN configuration {source} is neither JSON nor TOML ({exc})") from None
    if "transport" in data and isinstance(data["transport"], dict):
        data = data["transport"]
    if not isinstance(data, dict) or "interface" not in data:
        raise TransportError(f"CAN configuration {source} needs an interface key")
    return data


@TRANSPORTS.register("can")
def _can_factory(config: Mapping[str, Any], *, artifact: Any, **_context: Any) -> Transport:
    return CanTransport(config, artifact=artifact)
