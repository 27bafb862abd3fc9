"""Every status bit on every link: the bits as docs/design.md gives them, each law's own model as the oracle of a
command's bits, and the exchange of samples, resets and idle periods with a real node.

The expected bits are written out here from the documentation and never imported from the tables the links use
(``gainlink.shipping.flags`` and what it generates: ``gl_flags.h``, ``hil/links/base.py``'s ``STATUS_*``, the DBC):
a bit moved in any one of them then shows as a difference, where a test comparing a link with its own table would
pass. Over MAVLink the answer's raw flag word is checked too, at the positions the documentation gives.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.qformat import real
from gainlink.laws.lq.model import Float32Loop
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.laws.scheduled.reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE
from gainlink.shipping.artifact import Artifact

from .hil import udp_transport

#: A command's status as the Python side decodes it (``Command.status``), the numbering docs/design.md gives the CAN
#: command frames' status byte (the DBC's ``status``: bit0 fault, bit1 watchdog, bit2 a sample clipped, bit3 the
#: second-line saturation, then sigma held 0x10, clipped 0x20, rate-limited 0x40, reset 0x80).
FAULT, WATCHDOG, CLIPPED, OVERFLOW, RESET = 0x01, 0x02, 0x04, 0x08, 0x80
#: The MPC's cap stopped its solver (docs/design.md: bit 8; on CAN byte 3: its high nibble in a classic frame, the
#: flags' bits 8-15 in an FD frame, wire format 4).
CAPPED = 0x100
SIGMA_BITS = {SIGMA_HELD: 0x10, SIGMA_CLIPPED: 0x20, SIGMA_RATE: 0x40}  # the scheduled model's flag -> the link's bit
#: Where MAVLink carries them (docs/design.md, "Links"; wire format 4): HIL_ACTUATOR_CONTROLS.flags bits 0-15 are
#: MAVLink's own (bit 0 its LOCKSTEP flag) and stay clear, the status byte sits at bits 16-31, the saturation mask
#: (bit k: input k) at bits 32-47.
MAVLINK_STATUS_AT, MAVLINK_SAT_AT, MAVLINK_OWN = 16, 32, 0xFFFF


def scheduled_status(sigma_flags: np.ndarray, fault: np.ndarray) -> np.ndarray:
    """The status bits of a scheduled model's steps (its sigma flags and refusals), as docs/design.md numbers them:
    what a run's trace records per step (``RunTrace.flags``)."""
    bits = np.where(np.asarray(fault, dtype=bool), FAULT, 0).astype(np.int64)
    for flag, bit in SIGMA_BITS.items():
        bits |= np.where(np.asarray(sigma_flags, dtype=np.int64) & flag, bit, 0)
    return bits


#: The hang guard of one answer: a node answers in milliseconds; past this it hung or the link lost the frames.
ANSWER_GUARD_S = 10.0


@dataclass(frozen=True)
class Expected:
    """What the law's model says a step answers: the float32 command, the saturated inputs and the status bits."""

    u: np.ndarray
    saturated: np.ndarray
    status: int


class Float32Oracle:
    """The float32 law's bit-exact model (gainlink.laws.lq.model): fault on a refused sample, saturation."""

    def __init__(self, a: Artifact) -> None:
        self.a, self.loop = a, Float32Loop(a)

    def sample(self, y, r, s) -> Expected:
        st = self.loop.step(y, r)
        return Expected(np.float32(st.u), np.asarray(st.saturated), FAULT if st.fault else 0)

    def safe(self) -> np.ndarray:
        """u_op clamped into the limits."""
        return np.float32(np.clip(self.a.u_op, self.a.u_min, self.a.u_max))

    def reset(self) -> None:
        self.loop.reset()


class FixedOracle:
    """The integer law's bit-exact model (gainlink.laws.fixed.model): fault, a sample or reference clipped to its
    declared range, the second-line saturation (any variable it clipped), saturation."""

    def __init__(self, a: Artifact) -> None:
        self.loop = FixedPointLoop(a)

    def sample(self, y, r, s) -> Expected:
        st = self.loop.step_samples(y, r)
        status = FAULT if st.fault else 0
        status |= CLIPPED if np.any(st.clipped_y) or np.any(st.clipped_r) else 0
        status |= OVERFLOW if st.overflow else 0
        return Expected(self._real(st.U), np.asarray(st.saturated), status)

    def safe(self) -> np.ndarray:
        """The integers' safe command word, as the float the C returns."""
        return self._real(self.loop.c["U_SAFE"])

    def reset(self) -> None:
        self.loop.reset()

    def _real(self, words) -> np.ndarray:
        return np.float32(real(np.asarray(words, dtype=np.int64), self.loop.f["u"]))


class ScheduledOracle:
    """The scheduled law's float32 model (gainlink.laws.scheduled.model): fault, and sigma held, clipped and
    rate-limited, saturation."""

    def __init__(self, a: Artifact) -> None:
        self.loop = ScheduledFloat32Loop(a)

    def sample(self, y, r, s) -> Expected:
        st = self.loop.step(y, r, s)
        status = (FAULT if st.fault else 0) | sum(bit for flag, bit in SIGMA_BITS.items() if st.sigma_flags & flag)
        return Expected(np.float32(st.u), np.asarray(st.saturated), status)

    def safe(self) -> np.ndarray:
        """u_op at the held sigma, clamped."""
        return np.float32(self.loop.safe_command())

    def reset(self) -> None:
        self.loop.reset()


class MpcOracle:
    """The MPC law's float32 model (gainlink.laws.mpc.step, the C bit for bit): fault, the cap, saturation."""

    def __init__(self, a: Artifact) -> None:
        from gainlink.laws.mpc.arith import Float32
        from gainlink.laws.mpc.step import MpcLoop

        self.a, self.loop = a, MpcLoop(a, Float32())

    def sample(self, y, r, s) -> Expected:
        st = self.loop.step(y, r)
        status = FAULT if st.fault else (0 if st.converged else CAPPED)
        saturated = np.array([(st.sat >> j) & 1 for j in range(self.a.m)], dtype=bool)
        return Expected(np.float32(st.u), saturated, status)

    def safe(self) -> np.ndarray:
        """u_op clamped into the limits."""
        return np.float32(self.loop.law.safe)

    def reset(self) -> None:
        self.loop.reset()


def oracle(a: Artifact):
    """The model of the law ``a`` runs."""
    if a.mpc is not None:
        return MpcOracle(a)
    if a.schedule is not None:
        return ScheduledOracle(a)
    if a.checks.get("fixed_point") is not None:
        return FixedOracle(a)
    return Float32Oracle(a)


def answer(transport, frames: Sequence[Any], seq: int) -> Any:
    """Send ``frames`` and return the command answering ``seq`` (others, stale, are skipped)."""
    transport.send_frames(frames)
    while True:
        c = transport.receive_command(timeout=ANSWER_GUARD_S)
        assert c is not None, f"no answer to sample {seq} within {ANSWER_GUARD_S:g} s: the node hung or lost it"
        if c.seq == seq:
            return c


def sample_frames(transport, a: Artifact, seq: int, y, r, s) -> list:
    """One sample's frames: the external scheduling signals, when the law has any, travel after the references."""
    rs = np.concatenate([np.ravel(r), np.ravel(s)]) if a.schedule is not None and a.schedule.external else r
    return transport.encode_sample(seq=seq, y=np.asarray(y), r=np.asarray(rs))


def assert_answers(a: Artifact, transport, samples, *, mavlink: bool) -> int:
    """Every sample's answer through the link equals the model's: the command bit for bit, saturation and status.
    Over MAVLink the samples follow a reset and are followed by idle periods until the watchdog fires, then the last
    sample again. Returns the union of the status bits the link decoded (the caller checks it covers the law's)."""
    model, seq = oracle(a), 1
    if mavlink:
        model.reset()
        c = answer(transport, transport.encode_reset(seq=seq), seq)
        assert c.status == RESET, f"the reset's answer has status {c.status:#04x}"
        assert c.wire == RESET << MAVLINK_STATUS_AT, f"the reset's flags {c.wire:#x}"
        seq += 1
    seen, last = _samples(a, transport, model, samples, seq, mavlink=mavlink)
    if mavlink:
        seen |= _watchdog(a, transport, model, seq + len(samples), last=last, again=samples[-1])
    return seen


def _as_sent(sample) -> tuple[np.ndarray, ...]:
    """y, r, s as the link carries them: float32 values (as float64 arrays for the models)."""
    return tuple(np.float32(np.atleast_1d(v)).astype(np.float64) for v in sample)


def _samples(a: Artifact, transport, model, samples, seq: int, *, mavlink: bool) -> tuple[int, np.ndarray]:
    """Each sample through the link against the model; the status bits seen and the last command."""
    seen, u = 0, np.zeros(a.m, np.float32)
    for k, sample in enumerate(samples):
        y, r, s = _as_sent(sample)
        want = model.sample(y, r, s)
        c = answer(transport, sample_frames(transport, a, seq + k, y, r, s), seq + k)
        assert c.status == want.status, f"sample {k} {sample}: status {c.status:#04x}, the model's {want.status:#04x}"
        assert np.array_equal(c.saturated, want.saturated), (k, c.saturated, want.saturated)
        if mavlink:  # the bits where docs/design.md puts them, read from the message itself
            sat = sum(int(b) << j for j, b in enumerate(want.saturated))
            assert c.wire == (want.status << MAVLINK_STATUS_AT) | (sat << MAVLINK_SAT_AT), (k, hex(c.wire))
            assert c.wire & MAVLINK_OWN == 0, f"sample {k}: MAVLink's own bits set ({c.wire:#x})"
        u = np.float32(c.u)
        assert np.array_equal(u.view(np.uint32), want.u.view(np.uint32)), (k, c.u, want.u)
        seen |= c.status
    return seen, u


def _watchdog(a: Artifact, transport, model, seq: int, *, last: np.ndarray, again) -> int:
    """Idle periods: the last command held, then from the export's watchdog count on (gainlink.shipping.codegen:
    10 periods) the safe command with the watchdog bit, until the next sample, which is the law's again."""
    from gainlink.shipping.codegen import DEFAULT_WATCHDOG_PERIODS

    for k in range(1, DEFAULT_WATCHDOG_PERIODS + 2):
        c = answer(transport, transport.encode_idle(seq=seq), seq)
        seq += 1
        if k < DEFAULT_WATCHDOG_PERIODS:
            assert c.status == 0 and np.array_equal(np.float32(c.u), last), (k, c.status, c.u, last)
        else:
            assert c.status == WATCHDOG, f"idle period {k}: status {c.status:#04x}, not the watchdog's"
            assert c.wire == WATCHDOG << MAVLINK_STATUS_AT, f"idle period {k}: flags {c.wire:#x}"
            assert np.array_equal(np.float32(c.u), model.safe()), (k, c.u, model.safe())
    y, r, s = _as_sent(again)
    want = model.sample(y, r, s)
    c = answer(transport, sample_frames(transport, a, seq, y, r, s), seq)
    assert c.status == want.status and np.array_equal(np.float32(c.u), want.u), (c.status, c.u, want)
    return WATCHDOG


@contextmanager
def can_node(a: Artifact, executable, *, fd: bool = False) -> Iterator[Any]:
    """The host CAN node (gainlink_can) of ``a`` on a python-can udp_multicast bus of the test's own (classic
    frames, or CAN FD ones with ``fd``; float32 values); yields the open transport."""
    from gainlink.hil.links.can import CanTransport
    from gainlink.hil.loop.controller import ControllerProcess

    transport = CanTransport(udp_transport(fd=fd), artifact=a)
    peer = ControllerProcess([str(executable), *transport.controller_argv()])
    with ExitStack() as stack:
        transport.open()
        stack.callback(transport.close)
        stack.callback(peer.close)
        peer.start()
        peer.check_artifact(a.sha256)
        yield transport


@contextmanager
def mavlink_link(a: Artifact, url: str) -> Iterator[Any]:
    """The MAVLink HIL transport to the node at ``url`` (``udpout:`` the host app, ``tcp:`` an image's UART)."""
    from gainlink.hil.links.mavlink import MavlinkTransport

    m = a.m
    q = a.q + (len(a.schedule.external) if a.schedule is not None else 0)
    with MavlinkTransport(url=url, controller_url="", n_inputs=m, n_outputs=a.p, n_refs=q, ts=a.Ts) as t:
        yield t


@contextmanager
def image_node(a: Artifact, *, board: str, protocol: str) -> Iterator[Any]:
    """The Cortex-M image of ``a`` in QEMU serving ``protocol`` (``slcan`` or ``mavlink``) on its UART; yields the
    open transport. QEMU's lifetime (60 s) is the hang guard."""
    from gainlink.hil.links.can import CanTransport
    from gainlink.hil.links.mavlink import MavlinkTransport
    from gainlink.hil.loop.controller import qemu_peer

    from .net import tcp_port

    port = tcp_port()
    if protocol == "slcan":
        transport = CanTransport({"interface": "slcan", "channel": f"socket://127.0.0.1:{port}"}, artifact=a)
    else:
        q = a.q + (len(a.schedule.external) if a.schedule is not None else 0)
        transport = MavlinkTransport(
            url=f"tcp:127.0.0.1:{port}", controller_url="", n_inputs=a.m, n_outputs=a.p, n_refs=q, ts=a.Ts
        )
    image = qemu_peer(artifact=a, transport=transport, board=board, elf=None, duration_s=15.0)
    with ExitStack() as stack:
        stack.callback(image.close)
        image.start()
        image.check_artifact(a.sha256)
        transport.open()
        stack.callback(transport.close)
        yield transport
