"""HIL over CAN for a scheduled artifact: the firmware's CAN node (``gainlink_can`` built on the scheduled loop,
``gl_law.h``) answers each sample over the scenario's bus, as it does for an unscheduled one.

The run is the scheduled SIL's loop (:mod:`.sil_scheduled`: plant, sigma trace, closed-loop and model twins, the
report's ``schedule`` block) with the law behind the link: per step the sample (y then r) goes out in the CAN
layout, the command with the same sequence number comes back (the plant waits up to ``step_timeout``; a lost
command holds the last one). The external scheduling signals (``[schedule_signal.NAME]``), when the artifact has
any, travel in the sample after the references (``s_NAME`` in the layout and the DBC). Sigma is the node's own
(its flags come back in the status byte: held 0x10, clipped 0x20, rate-limited 0x40); its value is not on the bus,
so the trace's sigma is the scheduled float32 model's
(:class:`~gainlink.proof.scheduled_float32.ScheduledFloat32Loop`, bit for bit the C) on the samples the node
received. Lockstep, or ``mode = "realtime"`` with the host node: paced as the bridge is
(:func:`.scheduler.next_tick`), each command due by the next tick, and the bridge's timing block in the report. The
faults ``drop`` (the sample's frames not sent: no command, the last one held) and ``nan`` (its measured outputs sent
as NaN: the node refuses the sample whole, answers u_op at the held sigma with its fault bit, and raises no sigma
flag) are injected by the bridge's :class:`~.faults.FaultInjector`, counted in ``faults_injected``;
``refused_steps`` counts the answers with the fault bit; the trace records the plant's own sample.

With ``controller = "qemu"`` the node is the Cortex-M image's on its UART (slcan or MAVLink over a TCP socket;
``ports/cortex-m/sched-image.cmake``), the same node libraries on the same scheduled loop.

A MAVLink transport runs the same loop through the firmware's MAVLink node (``gainlink_mavlink`` on the scheduled
loop, ``gl_law.h``): the HIL sample carries y, r and then the external scheduling signals; the sigma flags come back
in HIL_ACTUATOR_CONTROLS' flags (the status flags 0x10, 0x20, 0x40, at bits 16-23), decoded to the same status bits.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from contextlib import ExitStack

import numpy as np
from gainlink.errors import ScenarioError
from gainlink.proof.scheduled_float32 import ScheduledFloat32Loop
from gainlink.proof.scheduled_reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE
from gainlink.shipping.artifact import Artifact

from ..links.base import STATUS_FAULT, STATUS_SIGMA_CLIPPED, STATUS_SIGMA_HELD, STATUS_SIGMA_RATE
from ..links.can import CanTransport
from ..links.config import transport_from_config
from ..links.mavlink import MavlinkTransport
from .bridge import RunResult
from .controller import ControllerProcess, controller_argv, qemu_peer
from .faults import FaultInjector
from .scenario import Scenario
from .scenario_plant import build_plant
from .sched_law import GL_ERR_NANINF, GL_SATURATED, SchedOut
from .scheduler import SPIN_NS, Pacer, cpu_latency_qos, gc_paused, next_tick, set_fifo, set_other
from .sil_scheduled import _closed_loop_twin, _ScheduledSil

#: The faults a scheduled run injects (:class:`.faults.FaultInjector`): the sample's frames not sent, its measured
#: outputs sent as NaN. The others change the order in which the node sees samples, which the sigma shadow does not
#: follow yet.
SCHEDULED_FAULTS = ("drop", "nan")

#: The scheduled node's status bits (firmware/apps/can/gl_can_layout.h) and the sigma flags they carry.
SIGMA_BITS = ((STATUS_SIGMA_HELD, SIGMA_HELD), (STATUS_SIGMA_CLIPPED, SIGMA_CLIPPED), (STATUS_SIGMA_RATE, SIGMA_RATE))


def check_scheduled_can(artifact: Artifact, scenario: Scenario) -> None:
    """One line when the scheduled artifact or the scenario cannot run over the CAN link."""
    kinds = sorted({f.kind for f in scenario.faults} - set(SCHEDULED_FAULTS))
    if kinds:
        raise ScenarioError(
            f"scenario {scenario.name}: a scheduled artifact runs over its link with the faults "
            f"{' and '.join(SCHEDULED_FAULTS)} only (faults {', '.join(kinds)})"
        )
    if scenario.mode == "realtime" and scenario.controller == "qemu":
        raise ScenarioError(
            f'scenario {scenario.name}: a scheduled artifact runs in real time with controller = "firmware" '
            '(the host node), not yet with "qemu"'
        )
    encoding = scenario.transport.get("encoding", "float32")
    if encoding != "float32" and any(f.kind == "nan" for f in scenario.faults):
        raise ScenarioError(f'scenario {scenario.name}: a nan fault needs encoding = "float32" (not "{encoding}")')


class _BusLaw:
    """The node behind the link, one sample a step (the interface of :class:`.sched_law.NativeScheduled`)."""

    def __init__(self, artifact: Artifact, scenario: Scenario, *, stack: ExitStack) -> None:
        transport = transport_from_config(scenario.transport, artifact=artifact)
        if not isinstance(transport, (CanTransport, MavlinkTransport)):
            raise ScenarioError(
                f"scenario {scenario.name}: a scheduled artifact runs over a CAN or MAVLink transport only"
            )
        if scenario.controller == "qemu":  # the image's node on its UART: QEMU serves, then the link connects
            self.peer, argv = _image_peer(artifact, scenario, transport=transport, stack=stack), None
        else:
            argv = controller_argv("firmware", artifact=artifact, artifact_path=scenario.artifact_path,
                                   transport=transport, executable=scenario.firmware)  # fmt: skip
            transport.open()
            stack.callback(transport.close)
            self.peer = ControllerProcess(argv)
            stack.callback(self.peer.close)
            self.peer.start()
            self.peer.check_artifact(artifact.sha256)
        self.transport, self.timeout = transport, scenario.step_timeout
        self.injector = FaultInjector(scenario.faults, Ts=artifact.Ts, seed=scenario.seed)
        self.shadow = ScheduledFloat32Loop(artifact)  # sigma's value (not on the bus)
        self.u = np.asarray(artifact.schedule.trim_at(artifact.schedule.points[0])[0], dtype=float)
        self.k, self.late = 0, 0
        self.due_ns: int | None = None  # a paced run's deadline for this step's command (perf_counter_ns)
        node = "gainlink_can" if isinstance(transport, CanTransport) else "gainlink_mavlink"
        if argv is None:
            node = f"the {scenario.board} image's {'slcan' if isinstance(transport, CanTransport) else 'MAVLink'} node"
        self.kind = {"kind": f"firmware ({node}, scheduled law, over the link)", "argv": argv}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> SchedOut | None:
        """Send sample ``y``, ``r`` (through the scenario's faults); the node's answer, or None when it did not come
        within ``step_timeout`` or the sample was dropped (lockstep: no answer can come, so none is waited for)."""
        k, seq = self.k, self.k % self.transport.seq_modulo
        self.k += 1
        y = self.injector.corrupt(k, y)
        rs = np.concatenate([r, s])  # the external scheduling signals travel after the references
        frames = self.injector.apply(k, self.transport.encode_sample(seq=seq, y=y, r=rs))
        if not frames:  # dropped: the node (and its sigma) never sees this sample
            return None
        ys, rx = self.transport.received_sample(y=y, r=rs)
        sigma = self.shadow.step(ys, rx[: r.size], rx[r.size :]).sigma
        self.transport.send_frames(frames)
        deadline = self.due_ns if self.due_ns is not None else time.perf_counter_ns() + int(self.timeout * 1e9)
        while (left := (deadline - time.perf_counter_ns()) / 1e9) > 0:
            c = self.transport.receive_command(timeout=left)
            if c is None:
                break
            if c.seq != seq:
                self.late += 1
                continue
            self.u = np.asarray(c.u, dtype=float)
            status = int(c.status)
            code = GL_ERR_NANINF if status & STATUS_FAULT else (GL_SATURATED if np.any(c.saturated) else 0)
            mask = int(np.sum(np.asarray(c.saturated, dtype=np.int64) << np.arange(len(c.saturated))))
            flags = sum(f for bit, f in SIGMA_BITS if status & bit)
            return SchedOut(u=self.u, status=code, sat_mask=mask, sigma=sigma, sigma_flags=flags)
        return None


def _image_peer(artifact: Artifact, scenario: Scenario, *, transport, stack: ExitStack):
    """The Cortex-M image in QEMU serving the link on its UART (started, checked), then the link opened."""
    peer = qemu_peer(artifact=artifact, transport=transport, board=scenario.board, elf=scenario.firmware,
                     duration_s=scenario.duration)  # fmt: skip
    stack.callback(peer.close)
    peer.start()
    peer.check_artifact(artifact.sha256)
    transport.open()
    stack.callback(transport.close)
    return peer


class _ScheduledCan(_ScheduledSil):
    """The scheduled SIL loop with the law behind the link: a lost command holds the last one. In real time each
    step waits for the pacer's tick (:func:`.scheduler.next_tick`, as the bridge does) and its command is due by
    the next one; ticks missed in a stall are held steps: the plant runs on under the last command, the node never
    sees those samples."""

    def __init__(self, artifact: Artifact, scenario: Scenario, *, plant, law: _BusLaw) -> None:
        super().__init__(artifact, scenario, plant=plant, law=law)
        self.mode = scenario.mode
        self.pacer: Pacer | None = None
        self.period_ns, self.overruns = int(round(self.plan.period_s * 1e9)), 0

    def _tick(self, k: int) -> int:
        if self.mode != "realtime":
            return k
        if self.pacer is None:
            self.pacer = Pacer(period_ns=self.period_ns)
        offset, start = self.pacer.start_ns - self.t_start, k
        k, due, woke = next_tick(self.pacer, k, steps=self.plan.N, skip=self.scenario.overrun == "skip",
                                 hold=lambda j, d: self._hold(j, d + offset))  # fmt: skip
        self.overruns += k - start
        if k < self.plan.N:
            self.rec.DUE[k], self.rec.TICK[k] = due + offset, woke + offset
            self.law.due_ns = self.pacer.start_ns + due + self.period_ns - SPIN_NS // 2
        return k

    def _hold(self, j: int, due: int) -> None:
        """A tick missed in a stall: the plant runs on under the last command (no sample sent, a deadline miss)."""
        rec = self.rec
        rec.Y[j], rec.U[j], rec.DUE[j], rec.TICK[j] = self.plant.outputs() + self.plan.noise[j], self.law.u, due, np.nan
        self.SIG[j] = self.SIG[j - 1] if j else self.sigma0
        self._advance(j)

    def _step(self, k: int) -> None:
        rec, plan = self.rec, self.plan
        y = self.plant.outputs() + plan.noise[k]
        rec.Y[k] = y
        if self.twin is not None:
            rec.X[k] = self.plant.state()
        t0 = time.perf_counter_ns()
        out = self.law.step(y, plan.R[k], self.S[k])
        t1 = time.perf_counter_ns()
        if self.mode != "realtime":
            rec.TICK[k] = t0 - self.t_start
        if out is not None:
            rec.GOT[k], rec.LAT[k], rec.ST[k] = True, t1 - t0, out.status
            rec.SAT[k] = ((out.sat_mask >> self.bits) & 1).astype(bool)
            self.SIG[k], self.FLAGS[k] = out.sigma, out.sigma_flags
        else:
            self.SIG[k] = self.SIG[k - 1] if k else self.sigma0
        rec.U[k] = self.law.u
        self._advance(k)

    def _advance(self, k: int) -> None:
        """The plant through step ``k`` under the command held, then the twins (same noise, reference, signals)."""
        plan = self.plan
        try:
            self.plant.advance(u=np.asarray(self.law.u, float) + plan.D[k], dt=self.a.Ts)
        finally:
            for twin in (self.twin, self.model_twin):
                if twin is not None:
                    twin.step(k, noise=plan.noise[k], r=plan.R[k], d=plan.D[k], s=self.S[k])


def over_can(scenario: Scenario) -> bool:
    """Whether a scheduled artifact's scenario runs the firmware's CAN node over its bus (else in process)."""
    config = scenario.transport
    kind = config.get("kind", "can" if "interface" in config else None)
    return scenario.controller == "firmware" and kind == "can"


def over_link(scenario: Scenario) -> bool:
    """Whether a scheduled artifact's scenario runs a firmware node (CAN or MAVLink: the host app, or with
    ``controller = "qemu"`` the Cortex-M image's on its UART) over its link (else in process)."""
    config = scenario.transport
    kind = config.get("kind", "can" if "interface" in config else None)
    return scenario.controller in ("firmware", "qemu") and kind in ("can", "mavlink")


def run_scheduled_can(
    artifact: Artifact, scenario: Scenario, *, progress: Callable[[int, int], None] | None = None
) -> RunResult:
    """Run ``scenario`` with the scheduled law in the firmware's CAN (or MAVLink) node over its link (module
    docstring)."""
    check_scheduled_can(artifact, scenario)
    plant = build_plant(scenario, artifact=artifact)
    realtime = scenario.mode == "realtime"
    with ExitStack() as stack:
        stack.callback(plant.close)
        law = _BusLaw(artifact, scenario, stack=stack)
        loop = _ScheduledCan(artifact, scenario, plant=plant, law=law)
        if scenario.twin:
            loop.twin = _closed_loop_twin(scenario, artifact=artifact, steps=loop.plan.N, stack=stack)
        if realtime:
            stack.enter_context(gc_paused())
        pm_qos = stack.enter_context(cpu_latency_qos()) if realtime and scenario.pm_qos else False
        fifo = _enter_fifo(scenario, peer=law.peer) if realtime else False
        try:
            result = loop.run(progress)
        finally:
            if fifo:
                set_other()
        code = law.peer.stop()
        peer = {"exit_status": code, "counters": law.peer.counters(), "stderr_bytes": law.peer.stderr_bytes()}
    m = dict(result.metrics, mode=scenario.mode, late=law.late, faults_injected=law.injector.counts)
    m["refused_steps"] = int(np.count_nonzero(result.trace.status == GL_ERR_NANINF))  # answered with the fault bit
    m["controller"] = peer  # read before the peer is closed (an image's QEMU drops its stderr then)
    if realtime:  # the bridge's real-time block
        m.update(sched_fifo=fifo, pm_qos=pm_qos, overruns=loop.overruns, overrun_policy=scenario.overrun)
    info = dict(result.info, transport=law.transport.describe())
    info["controller"] = dict(law.kind, ready=law.peer.ready_line)
    return dataclasses.replace(result, metrics=m, info=info)


def _enter_fifo(scenario: Scenario, *, peer: ControllerProcess) -> bool:
    """SCHED_FIFO for this process and the host node, when the scenario asks and the system permits."""
    fifo = set_fifo() if scenario.sched_fifo else False
    if fifo and peer.proc is not None:
        set_fifo(peer.proc.pid)
    return fifo
