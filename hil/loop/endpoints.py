"""What the closed loop (:mod:`.closed_loop`) hands each sample to, and gets the law's step back from.

- :class:`InProcess`: a :class:`~gainlink.laws.Controller` in this process (SIL: the law's float64 reference, or
  the host C through ctypes). No link, no peer, no pacing: ``latency_us`` is the time of the step call itself.
- :class:`OverFifos`: the law's replay-only Cortex-M image in QEMU over its semihosting FIFOs (PIL), one record
  each way per step (``Law.image_stream``); its records are kept for the law's own check.
- :class:`OverLink`: a peer behind a transport (HIL): the firmware's host app (CAN or MAVLink), the Python
  reference node, or the Cortex-M image in QEMU on its UART. The frame faults (drop, delay, duplicate, reorder)
  act on the frames sent, the process faults (silent, crash) on the peer; a command that does not come by the
  deadline leaves the step unanswered (the loop holds the last command). The link's commands carry the law's
  flags and saturation; a law whose step also reports a sigma the link does not carry (``Law.shadow``) has it
  from a shadow of the peer's law fed what the peer received, in the order it received it.

Both take the sample ``(y, r, s)`` in :meth:`send` and answer :meth:`receive` with a :class:`~gainlink.laws.Step`
or None, and fill the run's timing columns in the :class:`~.plan.Recorder`.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from gainlink.errors import ScenarioError, TransportError
from gainlink.laws import Step

from .closed_loop import Stop
from .faults import FaultInjector
from .plan import Recorder


class InProcess:
    """A controller stepped in this process (module docstring)."""

    def __init__(self, controller: Any, *, recorder: Recorder, safe_command: np.ndarray) -> None:
        self.controller, self.recorder, self._safe = controller, recorder, safe_command
        self.describe = dict(controller.describe)
        self._step: Step | None = None
        self._back = 0

    def safe_command(self) -> np.ndarray:
        """The command before the first answer."""
        return self._safe

    def begin(self, t_start: int) -> None:
        """The run starts (``perf_counter_ns``)."""
        self.t_start = t_start

    def peer_faults(self, k: int) -> None:
        """No peer: nothing to pause or kill."""

    def send(self, k: int, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> int:
        """Step the controller on the sample; returns when the step started (``perf_counter_ns``)."""
        t0 = time.perf_counter_ns()
        self._step = self.controller.step(y, r, s)
        self._back = time.perf_counter_ns()
        rec = self.recorder
        rec.LAT[k], rec.SENT[k], rec.BACK[k] = self._back - t0, t0 - self.t_start, self._back - self.t_start
        return t0

    def receive(self, k: int, *, deadline: int | None) -> Step | None:
        """The step of the sample just sent."""
        return self._step

    def no_answer(self, k: int) -> None:
        """Never: an in-process controller always answers."""


class OverFifos:
    """The law's image in QEMU over its FIFOs (module docstring): ``link`` is ``(process, in fd, out fd)`` with the
    stream's header exchanged; ``read(fd, size, proc=, deadline_s=)`` reads a whole record or raises."""

    def __init__(self, stream: Any, *, link: tuple, recorder: Recorder, deadline_s: float, steps: int,
                 safe_command: np.ndarray, read: Any) -> None:  # fmt: skip
        self.stream, self.recorder, self._safe, self._read = stream, recorder, safe_command, read
        self.proc, self.fin, self.fout = link
        self.deadline_s = deadline_s
        self.records = np.zeros(steps, dtype=stream.dout)
        self.describe = {"kind": "qemu (the image over semihosting FIFOs)", "elf": str(stream.elf)}
        self._sent = 0

    def safe_command(self) -> np.ndarray:
        """The command before the first answer."""
        return self._safe

    def begin(self, t_start: int) -> None:
        """The run starts (``perf_counter_ns``)."""
        self.t_start = t_start

    def peer_faults(self, k: int) -> None:
        """No process faults on the image."""

    def send(self, k: int, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> int:
        """Write sample ``k``'s record; returns when (``perf_counter_ns``)."""
        import os

        self._sent = time.perf_counter_ns()
        os.write(self.fin, self.stream.sample(y, r, s))
        self.recorder.SENT[k] = self._sent - self.t_start
        return self._sent

    def receive(self, k: int, *, deadline: int | None) -> Step:
        """The image's record for sample ``k`` (it answers every record, or the read fails in one line)."""
        raw = self._read(self.fout, self.stream.dout.itemsize, proc=self.proc, deadline_s=self.deadline_s)
        back = time.perf_counter_ns()
        rec = self.recorder
        rec.LAT[k], rec.BACK[k] = back - self._sent, back - self.t_start
        self.records[k] = np.frombuffer(raw, dtype=self.stream.dout)[0]
        return self.stream.decode(self.records[k])

    def no_answer(self, k: int) -> None:
        """Never: the image answers every record."""


class OverLink:
    """A peer behind a transport (module docstring).

    Parameters
    ----------
    transport : Transport
        Open, and the peer ready (:func:`~.bridge.start_peer` starts both in the order the link needs).
    peer : ControllerProcess or QemuUart
        Paused by a ``silent`` fault, killed by a ``crash`` fault, asked why when no command comes.
    injector : FaultInjector
        The scenario's frame faults.
    shadow : Controller, optional
        The peer's law in this process, fed what the peer received (the sigma the commands do not carry).
    """

    def __init__(self, *, transport: Any, peer: Any, recorder: Recorder, injector: FaultInjector, plan: Any,
                 safe_command: np.ndarray, step_timeout: float, peer_timeout: float, Ts: float,
                 shadow: Any = None) -> None:  # fmt: skip
        self.transport, self.peer, self.recorder, self.injector = transport, peer, recorder, injector
        self.plan, self._safe, self.Ts = plan, safe_command, Ts
        self.step_timeout_ns, self.peer_timeout = int(step_timeout * 1e9), peer_timeout
        self.shadow, self.sigma = shadow, {}
        self.q = plan.R.shape[1]
        self.modulo = transport.seq_modulo
        self._sat: dict[bytes, int] = {}  # a command's saturation flags -> their bits
        self._direct = not injector.faults and shadow is None
        self.late = 0
        self.silent_since_ns: int | None = None
        self.silent_since_step = 0  # the first sample of the current silence (lockstep runs faster than Ts)
        self.silent_at, self.crash_at = plan.silent_at, plan.crash_at
        self._sent_ns = 0
        self._pending = False  # a frame of this step's sample went out: its command can come

    def safe_command(self) -> np.ndarray:
        """The command before the first answer."""
        return self._safe

    def begin(self, t_start: int) -> None:
        """The run starts (``perf_counter_ns``)."""
        self.t_start = t_start

    def peer_faults(self, k: int) -> None:
        """Pause or kill the peer at the step the scenario's silent/crash fault names."""
        if self.silent_at is not None and k >= self.silent_at:
            self.peer.pause()
            self.silent_at = None
        if self.crash_at is not None and k >= self.crash_at:
            self.peer.kill()
            self.crash_at = None

    def send(self, k: int, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> int:
        """Encode the sample (external signals after the references), pass it through the frame faults and send
        what goes out now; returns when (``perf_counter_ns``)."""
        tr = self.transport
        rs = np.concatenate([r, s]) if s.size else r
        frames = tr.encode_sample(seq=k % self.modulo, y=y, r=rs)
        if self._direct:  # no frame fault, no shadow: the sample's frames, now
            sent = self._sent_ns = time.perf_counter_ns()
            self._send(k, frames)
            self._pending = True
            self.recorder.SENT[k] = sent - self.t_start
            return sent
        units = self.injector.apply(k, (y, rs, frames))
        sent = time.perf_counter_ns()
        self._pending = False
        for j, (yj, rsj, frames) in units:
            if self.shadow is not None and tr.steps_on(j % self.modulo):
                ys, rx = tr.received_sample(y=yj, r=rsj)
                self.sigma.setdefault(j, self.shadow.step(ys, rx[: self.q], rx[self.q :]).sigma)
            self._send(k, frames)
            self._pending |= j == k
        self._sent_ns = sent
        self.recorder.SENT[k] = sent - self.t_start
        return sent

    def _send(self, k: int, frames: list) -> None:
        """Send frames; a link that breaks because the controller died ends the run with that reason."""
        try:
            self.transport.send_frames(frames)
        except TransportError:
            # A serial link (QEMU's UART socket) fails on write as soon as its peer is gone; the exit status
            # follows a moment later, and is the reason the user needs.
            until = time.monotonic() + 2.0
            while self.peer.exit_status() is None and time.monotonic() < until:
                time.sleep(0.01)
            if self.peer.exit_status() is None:
                raise
            self.no_answer(k)

    def receive(self, k: int, *, deadline: int | None) -> Step | None:
        """The command answering sample ``k`` before ``deadline`` (``perf_counter_ns``; lockstep: ``step_timeout``
        after the send), or None; older ones count as late, and their arrival is recorded for the service time
        (:func:`~.metrics.link_capacity`). Nothing is waited for when no frame of sample ``k`` went out."""
        if not self._pending:
            return None
        sent, rec, seq = self._sent_ns, self.recorder, k % self.modulo
        deadline = deadline if deadline is not None else sent + self.step_timeout_ns
        while True:
            left = (deadline - time.perf_counter_ns()) / 1e9
            if left <= 0:
                return None
            c = self.transport.receive_command(timeout=left)
            if c is None:
                return None
            if c.seq == seq:
                rec.LAT[k], rec.BACK[k] = c.t_ns - sent, c.t_ns - self.t_start
                self.silent_since_ns = None
                key = c.saturated.tobytes()
                sat = self._sat.get(key)
                if sat is None:
                    sat = self._sat[key] = sum(1 << j for j, b in enumerate(c.saturated) if b)
                return Step(u=c.u, flags=c.status, sat=sat, sigma=self.sigma.pop(k, np.nan) if self.sigma else np.nan)
            self.late += 1
            j = k - (seq - c.seq) % self.modulo  # the latest earlier sample with that seq
            if 0 <= j < k and np.isnan(rec.BACK[j]):
                rec.BACK[j] = c.t_ns - self.t_start

    def no_answer(self, k: int) -> None:
        """No command for step ``k``: stop the run if the peer exited or has been silent too long."""
        Ts = self.Ts
        now = time.perf_counter_ns()
        if self.silent_since_ns is None:
            self.silent_since_ns, self.silent_since_step = self._sent_ns or now, k
        code = self.peer.exit_status()
        if code is not None:
            raise Stop(f"controller exited with status {code} at step {k} (t={k * Ts:.3f} s){_tail(self.peer)}", k + 1)
        if now - self.silent_since_ns >= self.peer_timeout * 1e9:
            raise Stop(
                f"controller silent for {self.peer_timeout:g} s since step {self.silent_since_step} (no command for "
                f"sample {k}, t={k * Ts:.3f} s)" + self.transport.silence_hint(),
                k + 1,
            )


def _tail(peer: Any) -> str:
    text = peer.stderr_tail()
    return f": {text}" if text else ""


def refuse_link_faults(scenario: Any) -> None:
    """One line when an in-process run is asked for what only a link or a peer has: frame or process faults, real
    time."""
    kinds = sorted({f.kind for f in scenario.faults} - {"nan"})
    if kinds:
        raise ScenarioError(
            f"scenario {scenario.name}: faults ({', '.join(kinds)}) act on a link or a controller process; "
            "a SIL run has neither (run it as HIL)"
        )
    if scenario.mode == "realtime":
        raise ScenarioError(f'scenario {scenario.name}: a SIL run is not paced; mode = "realtime" needs HIL')
