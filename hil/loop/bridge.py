"""The HIL bridge: plant on this side, controller peer on the other side of a transport.

:func:`run_scenario` builds the plant and the transport from the scenario, starts the controller
process, runs the loop in lockstep (the plant waits for each command, up to ``step_timeout``) or in
real time (fixed period, sleep-then-spin to absolute deadlines, SCHED_FIFO and a 0 us CPU wake-up
latency request when permitted), and always stops the peer. A peer that dies, or stays silent for
``peer_timeout``, ends the run early with ``complete = False`` and the reason.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

import numpy as np
from gainlink.errors import PlantError, ScenarioError, TransportError
from gainlink.shipping.artifact import Artifact, load
from gainlink.shipping.codegen_fixed import is_fixed

from ..links.base import Transport
from ..links.config import transport_from_config
from ..plants.base import Plant
from .controller import ControllerProcess, controller_argv, qemu_peer
from .faults import SAMPLE_FAULTS, FaultInjector
from .metrics import RunTrace, compute_metrics, link_capacity
from .plan import Recorder, describe_artifact, describe_plant, plan_run, start_model_twin, start_twin, step_twins
from .scenario import Scenario
from .scenario_plant import build_plant
from .scheduler import (
    SPIN_NS,
    Pacer,
    Placement,
    cpu_latency_qos,
    gc_paused,
    next_tick,
    resolve_affinity,
    set_fifo,
    set_other,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunResult:
    """The outcome of one run: metrics (as in report.json), the trace, and what ran."""

    scenario: Scenario
    metrics: dict
    trace: RunTrace
    complete: bool
    reason: str | None
    info: dict


def prepare(scenario: Scenario) -> tuple[Artifact, Plant]:
    """Load the artifact and build the plant, checking that they fit each other."""
    artifact = load(scenario.artifact_path)
    return artifact, build_plant(scenario, artifact=artifact)


def run_scenario(scenario: Scenario, *, progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Run a scenario end to end (see the module docstring).

    Parameters
    ----------
    scenario : Scenario
        The parsed scenario.
    progress : callable, optional
        Called as ``progress(done, total)`` every few hundred steps.

    Returns
    -------
    RunResult
    """
    if any(f.kind in SAMPLE_FAULTS for f in scenario.faults):
        raise ScenarioError(f"scenario {scenario.name}: nan faults run with a scheduled artifact over its link only")
    artifact, plant = prepare(scenario)
    with ExitStack() as stack:
        stack.callback(plant.close)
        transport = transport_from_config(scenario.transport, artifact=artifact)
        peer = _start_peer(scenario, artifact=artifact, transport=transport, stack=stack)
        busy_poll = bool(scenario.transport.get("busy_poll_us", 0))
        cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
        affinity = "none" if scenario.controller == "qemu" and scenario.affinity == "auto" else scenario.affinity
        placement = stack.enter_context(
            Placement(
                resolve_affinity(affinity, mode=scenario.mode, busy_poll=busy_poll, cpus=cpus),
                peer_pid=peer.proc.pid if peer.proc is not None else None,
            )
        )
        stack.enter_context(gc_paused())
        pm_qos = stack.enter_context(cpu_latency_qos()) if scenario.mode == "realtime" and scenario.pm_qos else False
        loop = _Loop(scenario, artifact=artifact, plant=plant, transport=transport, peer=peer)
        loop.twin = start_twin(scenario, artifact=artifact, plan=loop.plan, stack=stack)
        result = loop.run(progress)
        if scenario.controller == "qemu":
            transport.close()  # the UART's client leaves before the board powers off (slcan's close writes to it)
        code = peer.stop()  # its exit summary counts everything it received, hostile traffic included
        result.metrics["controller"] = {
            "exit_status": code,
            "counters": peer.counters(),
            "stderr_bytes": peer.stderr_bytes(),
        }
        result.metrics["cpu"] = placement.describe()
        if scenario.mode == "realtime":
            result.metrics["pm_qos"] = pm_qos
        clipped = result.info["transport"].get("encoding_clipped")
        if clipped is not None:
            result.metrics["encoding_clipped"] = clipped
        if is_fixed(artifact):  # which law answered, checked against the integer model and the float64 law
            from .can_fixed import fixed_can_check  # (and the firmware tooling it needs: only for a fixed artifact)

            result.metrics["fixed_point"] = fixed_can_check(
                artifact, result.trace, ready_line=peer.ready_line, model_plant=is_design_model(scenario)
            )
        return result


def is_design_model(scenario: Scenario) -> bool:
    """Whether the plant is the artifact's own model (``kind = "linear"`` from the scenario's artifact, unperturbed):
    the loop a fixed-point certificate's closed-loop bounds are about."""
    return scenario.plant.get("kind") == "linear" and set(scenario.plant) <= {"kind"}


def _start_peer(scenario: Scenario, *, artifact: Artifact, transport: Transport, stack: ExitStack) -> Any:
    """Open the link and start the controller peer, in the order the link needs; both are closed by ``stack``.

    A host process connects to a link the bridge has opened; the image in QEMU serves its UART, so QEMU
    starts (and prints its banner) before the bridge connects.
    """
    if scenario.controller == "qemu":
        peer = qemu_peer(
            artifact=artifact,
            transport=transport,
            board=scenario.board,
            elf=scenario.firmware,
            duration_s=scenario.duration,
        )
        stack.callback(peer.close)
        peer.start()
        peer.check_artifact(artifact.sha256)
        transport.open()
        stack.callback(transport.close)
        return peer
    argv = controller_argv(
        scenario.controller,
        artifact=artifact,
        artifact_path=scenario.artifact_path,
        transport=transport,
        executable=scenario.firmware,
    )
    transport.open()
    stack.callback(transport.close)
    peer = ControllerProcess(argv)
    stack.callback(peer.close)
    peer.start()
    peer.check_artifact(artifact.sha256)
    return peer


class _Stop(Exception):
    """Ends the loop early: the run is incomplete for ``reason`` after ``steps`` steps."""

    def __init__(self, reason: str, steps: int) -> None:
        super().__init__(reason)
        self.reason, self.steps = reason, steps


class _Loop:
    """One run's loop, step by step: sample the plant, send, wait for the command, advance the plant.

    State carried between steps: the command being applied, the count of late (stale) commands, when
    the peer went silent, and the overruns of a real-time run.
    """

    def __init__(
        self, scenario: Scenario, *, artifact: Artifact, plant: Plant, transport: Transport, peer: ControllerProcess
    ) -> None:
        self.scenario, self.a, self.plant, self.transport, self.peer = scenario, artifact, plant, transport, peer
        self.plan = plan_run(scenario, artifact=artifact, plant=plant)
        self.rec = Recorder(self.plan, artifact=artifact, plant=plant)
        self.injector = FaultInjector(scenario.faults, Ts=artifact.Ts, seed=scenario.seed)
        self.twin = None  # the float64 twin (gainlink.proof.twin), set by run_scenario when the scenario has one
        self.model_twin, self.model_start = None, ""  # the model twin (.model_twin), started with the run
        self.u = artifact.safe_command  # until the first command: u_op clamped into the limits
        self.late = 0
        self.overruns = 0
        self.silent_since_ns: int | None = None
        self.silent_since_step = 0  # the first sample of the current silence (lockstep runs faster than Ts)
        self.period_ns = int(round(self.plan.period_s * 1e9))
        self.silent_at, self.crash_at = self.plan.silent_at, self.plan.crash_at

    def run(self, progress: Callable[[int, int], None] | None) -> RunResult:
        """Run every planned step (or until the peer or the plant fails) and return the result."""
        N = self.plan.N
        self.plant.reset(initial=self.scenario.initial_state)
        self.model_twin, self.model_start = start_model_twin(
            self.scenario, artifact=self.a, plan=self.plan, plant=self.plant
        )
        fifo = self._enter_fifo()
        every = max(1, N // 100)
        self.t_start = time.perf_counter_ns()
        self.pacer = Pacer(period_ns=self.period_ns)
        k, reason = 0, None
        try:
            while k < N:
                self._peer_faults(k)
                wait_until = None
                if self.plan.realtime:
                    k, wait_until = self._next_tick(k)
                    if k >= N:
                        break
                self._step(k, wait_until)
                k += 1
                if progress is not None and k % every == 0:
                    progress(k, N)
        except _Stop as stop:
            k, reason = stop.steps, stop.reason
        except PlantError as exc:  # in an overrun's held steps
            reason = f"plant failed at step {k}: {exc}"
        finally:
            if fifo:
                set_other()
        if progress is not None:
            progress(k, N)
        return self._result(k, reason=reason, fifo=fifo)

    def _enter_fifo(self) -> bool:
        if not (self.plan.realtime and self.scenario.sched_fifo):
            return False
        fifo = set_fifo()
        if fifo and self.peer.proc is not None and self.scenario.controller != "qemu":
            set_fifo(self.peer.proc.pid)  # QEMU's threads stay SCHED_OTHER: its vCPU must not starve its I/O thread
        return fifo

    def _peer_faults(self, k: int) -> None:
        """Pause or kill the peer at the step the scenario's silent/crash fault names."""
        if self.silent_at is not None and k >= self.silent_at:
            self.peer.pause()
            self.silent_at = None
        if self.crash_at is not None and k >= self.crash_at:
            self.peer.kill()
            self.crash_at = None

    def _next_tick(self, k: int) -> tuple[int, int]:
        """Wait for the pacer's next tick; returns the step to run and when its command is due (absolute ns).

        Ticks that passed while the bridge was stalled (an overrun) are held steps of the plant: it runs
        on under the last command, as a real one would, and each is a deadline miss.
        """
        offset = self.pacer.start_ns - self.t_start
        start, N = k, self.plan.N
        k, due_rel, woke_rel = next_tick(self.pacer, k, steps=N, skip=self.scenario.overrun == "skip",
                                         hold=lambda j, due: self._hold(j, due + offset))  # fmt: skip
        self.overruns += k - start
        if k >= N:
            return k, 0
        self.rec.DUE[k] = due_rel + offset
        self.rec.TICK[k] = woke_rel + offset
        return k, self.pacer.start_ns + due_rel + self.period_ns - SPIN_NS // 2

    def _hold(self, j: int, due: int) -> None:
        """A tick missed in an overrun: the plant runs on under the last command (never sent: no jitter, a miss)."""
        rec = self.rec
        rec.Y[j] = self.plant.outputs() + self.plan.noise[j]
        rec.U[j] = self.u
        rec.DUE[j] = due
        rec.TICK[j] = np.nan
        self.plant.advance(u=self.u + self.plan.D[j], dt=self.a.Ts)
        self._twin_step(j)

    def _step(self, k: int, wait_until: int | None) -> None:
        """Sample, send, wait for the command of this sample, and advance the plant by one period."""
        rec, plan, a = self.rec, self.plan, self.a
        y = self.plant.outputs() + plan.noise[k]
        rec.Y[k] = y
        if self.twin is not None:
            rec.X[k] = self.plant.state()  # an FMU call per step: only with the twin on
        seq = k % self.transport.seq_modulo
        frames = self.injector.apply(k, self.transport.encode_sample(seq=seq, y=y, r=plan.R[k]))
        sent = time.perf_counter_ns()
        if wait_until is None:
            rec.TICK[k] = sent - self.t_start
        self._send(k, frames)
        rec.SENT[k] = sent - self.t_start
        deadline = wait_until if wait_until is not None else sent + int(self.scenario.step_timeout * 1e9)
        try:
            cmd = self._await_command(k, seq, deadline)
            if cmd is not None:
                self.u = cmd.u
                rec.GOT[k], rec.LAT[k], rec.SAT[k], rec.ST[k] = True, cmd.t_ns - sent, cmd.saturated, cmd.status
                rec.BACK[k] = cmd.t_ns - self.t_start
                self.silent_since_ns = None
            else:
                self._check_peer(k, sent)
            rec.U[k] = self.u
            try:
                self.plant.advance(u=self.u + plan.D[k], dt=a.Ts)
            except PlantError as exc:
                raise _Stop(f"plant failed at step {k}: {exc}", k + 1) from None
        finally:  # after the command: the twin's work never delays the controller or its measured latency
            self._twin_step(k)

    def _send(self, k: int, frames: list) -> None:
        """Send sample ``k``; a link that breaks because the controller died ends the run with that reason."""
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
            self._check_peer(k, time.perf_counter_ns())

    def _twin_step(self, k: int) -> None:
        """Advance the float64 twin and the model twin through sample ``k`` (same noise, reference, disturbance)."""
        step_twins((self.twin, self.model_twin), k, self.plan)

    def _await_command(self, k: int, seq: int, deadline: int):
        """The command answering sample ``k`` (``seq`` on the link) before ``deadline`` (ns), or None; older ones
        count as late, and their arrival is recorded for the service time (:func:`~.metrics.link_capacity`)."""
        while True:
            left = (deadline - time.perf_counter_ns()) / 1e9
            if left <= 0:
                return None
            c = self.transport.receive_command(timeout=left)
            if c is None:
                return None
            if c.seq == seq:
                return c
            self.late += 1
            j = k - (seq - c.seq) % self.transport.seq_modulo  # the latest earlier sample with that seq
            if 0 <= j < k and np.isnan(self.rec.BACK[j]):
                self.rec.BACK[j] = c.t_ns - self.t_start

    def _check_peer(self, k: int, sent: int) -> None:
        """No command for step ``k``: stop the run if the peer exited or has been silent too long."""
        Ts = self.a.Ts
        now = time.perf_counter_ns()
        if self.silent_since_ns is None:
            self.silent_since_ns, self.silent_since_step = sent, k
        code = self.peer.exit_status()
        if code is not None:
            self.rec.U[k] = self.u
            raise _Stop(f"controller exited with status {code} at step {k} (t={k * Ts:.3f} s){_tail(self.peer)}", k + 1)
        timeout = self.scenario.peer_timeout
        if now - self.silent_since_ns >= timeout * 1e9:
            self.rec.U[k] = self.u
            raise _Stop(
                f"controller silent for {timeout:g} s since step {self.silent_since_step} (no command for sample {k}, "
                f"t={k * Ts:.3f} s)" + self.transport.silence_hint(),
                k + 1,
            )

    def _result(self, steps: int, *, reason: str | None, fifo: bool) -> RunResult:
        """Metrics, trace and what ran, for ``steps`` steps."""
        a, scenario = self.a, self.scenario
        complete = reason is None
        trace = self.rec.trace(steps, self.twin, self.model_twin)
        metrics = compute_metrics(
            trace,
            artifact=a,
            mode=scenario.mode,
            late=self.late,
            period_s=self.plan.period_s,
            model_start=self.model_start,
        )
        wall = (time.perf_counter_ns() - self.t_start) / 1e9
        metrics.update(
            {
                "complete": complete,
                "steps_planned": self.plan.N,
                "wall_s": wall,
                "steps_per_s": steps / wall if wall > 0 else None,
                "sched_fifo": fifo,
                "faults_injected": self.injector.counts,
                "mode": scenario.mode,
            }
        )
        if self.plan.realtime:
            metrics["overruns"] = self.overruns
            metrics["overrun_policy"] = scenario.overrun
        if reason:
            metrics["reason"] = reason
        plant = self.plant
        info = {
            "artifact": describe_artifact(a, scenario.artifact_path),
            "plant": describe_plant(plant),
            "transport": self.transport.describe(),
            "controller": {"kind": scenario.controller, "argv": self.peer.argv, "ready": self.peer.ready_line},
        }
        from gainlink.firmware.uart import gains_of

        gains = gains_of(self.peer.ready_line)
        if gains is not None:  # the set the node said it runs (a MAVLink node: always the artifact's, checked at start)
            info["controller"]["gains"] = gains
        if scenario.controller == "qemu":
            info["controller"]["board"] = scenario.board
            metrics["uart"] = link_capacity(self.rec.SENT[:steps], self.rec.BACK[:steps], answered_in_time=trace.got)
        return RunResult(scenario=scenario, metrics=metrics, trace=trace, complete=complete, reason=reason, info=info)


def _tail(peer: ControllerProcess) -> str:
    text = peer.stderr_tail()
    return f": {text}" if text else ""
