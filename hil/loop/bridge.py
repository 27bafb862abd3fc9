"""One run of a scenario, whoever runs the law: the one dispatcher (``gainlink.hil.run``, ``gainlink hil run``,
campaigns, the studies and the showcase all call :func:`run_scenario`).

The run is planned first (:mod:`.plan`: references, noise, disturbances, external scheduling signals, faults;
nothing built, no peer started), then its endpoint is chosen by the scenario (:mod:`.endpoints`):

- no ``[transport]`` (an empty table): in process (SIL), ``controller = "reference"`` the law's float64 reference,
  ``"firmware"`` the host C of the law through ctypes (``Law.native``);
- a CAN or MAVLink ``[transport]``: over the link (HIL), ``controller = "firmware"`` the firmware's host app for
  that link, ``"reference"`` the Python reference node (the law's float64 reference on the link), ``"qemu"`` the
  Cortex-M image of ``board`` in QEMU serving the link on its UART. The link is opened and the peer started in the
  order the link needs, both always stopped; in lockstep the plant waits for each command up to ``step_timeout``,
  in real time it is paced (SCHED_FIFO and a 0 us CPU wake-up latency request when permitted, CPU placement by
  ``affinity``). A peer that dies, or stays silent for ``peer_timeout``, ends the run early with
  ``complete = False`` and the reason.

The same loop runs every case (:mod:`.closed_loop`), for every law (:func:`gainlink.laws.law_of`); the twins are
computed from the plan after the run (:mod:`.twins`), and the law adds its own report blocks
(``Law.run_report``: a fixed-point law's check against its integer model and certificate, a scheduled law's sigma).
The artifact travels as an object; a peer process that reads a file (the Python reference node) gets one written
once.
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gainlink.errors import ScenarioError
from gainlink.laws import law_of
from gainlink.shipping.artifact import Artifact, load

from ..links.config import transport_from_config
from ..plants.base import Plant
from .closed_loop import ClosedLoop, Outcome
from .controller import ControllerProcess, controller_argv, qemu_peer
from .endpoints import InProcess, OverLink, refuse_link_faults
from .faults import FaultInjector
from .metrics import RunTrace, compute_metrics, link_capacity
from .plan import Plan, Recorder, describe_artifact, describe_plant, plan_like, plan_run
from .scenario import Scenario
from .scenario_plant import build_plant
from .scheduler import Placement, cpu_latency_qos, gc_paused, resolve_affinity, set_fifo, set_other
from .teardown import ClosingStack
from .twins import TwinStart, run_twins, twin_start

log = logging.getLogger(__name__)

__all__ = ["Run", "RunResult", "build_plant", "is_design_model", "prepare_run", "run_scenario"]


@dataclass(frozen=True)
class RunResult:
    """The outcome of one run: metrics (as in report.json), the trace, what ran, and the artifact that ran."""

    scenario: Scenario
    metrics: dict
    trace: RunTrace
    complete: bool
    reason: str | None
    info: dict
    artifact: Artifact


def is_design_model(scenario: Scenario) -> bool:
    """Whether the plant is the artifact's own model (``kind = "linear"`` from the scenario's artifact, unperturbed):
    the loop a fixed-point certificate's closed-loop bounds are about."""
    return scenario.plant.get("kind") == "linear" and set(scenario.plant) <= {"kind"}


def in_process(scenario: Scenario) -> bool:
    """Whether ``scenario`` runs its law in this process (no ``[transport]``), else over its link."""
    return not scenario.transport


def run_scenario(
    scenario: Scenario,
    *,
    artifact: Artifact | str | Path | None = None,
    library: Path | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RunResult:
    """Run ``scenario`` end to end (module docstring).

    Parameters
    ----------
    scenario : Scenario
        The parsed scenario.
    artifact : Artifact or path, optional
        The artifact to run (default: the scenario's ``artifact`` file).
    library : Path, optional
        A prebuilt host library of this artifact for an in-process ``controller = "firmware"`` (default: built
        and cached by sha256).
    progress : callable, optional
        Called as ``progress(done, total)`` every hundredth of the run.

    Returns
    -------
    RunResult
        ``complete`` is False, with the reason, when the plant fails or the peer dies or stays silent.
    """
    a, source = _artifact(scenario, artifact)
    law = law_of(a)
    if not scenario.sigma_rate_limit:  # another artifact: a library built for the given one does not serve it
        a, library = law.without_rate_limit(a), None
    _check(scenario)
    plant = build_plant(scenario, artifact=a)
    with ClosingStack() as stack:
        stack.callback(plant.close)
        run = prepare_run(scenario, law=law, artifact=a, plant=plant, source=source)
        start, plan = run.start, run.plan
        if in_process(scenario):
            outcome = run.in_process(library=library, progress=progress)
        else:
            outcome = run.over_link(stack, progress=progress)
        stack.closing()  # the link, the peer and the plant close whole, a Ctrl-C after them
    t0 = time.perf_counter()
    twins = run_twins(law, a, scenario=scenario, plan=plan, start=start, steps=outcome.steps,
                      build=lambda: build_plant(scenario, artifact=a))  # fmt: skip
    twins_s = time.perf_counter() - t0
    return run.result(outcome, twins=twins, twins_s=twins_s)


def _artifact(scenario: Scenario, artifact: Artifact | str | Path | None) -> tuple[Artifact, str]:
    """The artifact object of a run (the one given, or loaded once from a path or the scenario's file), and where
    it came from, for the report."""
    if isinstance(artifact, Artifact):
        return artifact, "(given as an object)"
    path = Path(artifact) if artifact is not None else scenario.artifact_path
    return load(path), str(path)


def _check(scenario: Scenario) -> None:
    """What is refused before the plant is built: what only a link has, in process; a NaN sample on a link that
    cannot carry one."""
    if in_process(scenario):
        refuse_link_faults(scenario)
        if scenario.controller == "qemu":
            raise ScenarioError(
                f'scenario {scenario.name}: controller = "qemu" serves the image\'s UART: give it a [transport] '
                '(interface = "slcan" or kind = "mavlink" with url = "tcp:HOST:PORT")'
            )
        return
    encoding = scenario.transport.get("encoding", "float32")
    if encoding != "float32" and any(f.kind == "nan" for f in scenario.faults):
        raise ScenarioError(f'scenario {scenario.name}: a nan fault needs encoding = "float32" (not "{encoding}")')


def prepare_run(scenario: Scenario, *, law, artifact: Artifact, plant: Plant, source: str, record: bool = True,
                like: Run | None = None) -> Run:  # fmt: skip
    """A run of ``scenario`` ready to step: ``plant`` reset to its initial state, the plan made (before anything is
    built or started) and where the model twin starts (a campaign block prepares each of its runs so, ``record``
    False: its recorder's arrays are the block's; ``like``: a run of the same law and artifact that differs from this
    one only in its seed and its plant's drawn numbers: its plan taken with this run's noise,
    :func:`~.plan.plan_like`, and what :class:`Run` shares with it)."""
    plant.reset(initial=scenario.initial_state)
    if like is not None:
        plan = plan_like(like.plan, scenario, law=law, artifact=artifact, plant=plant)
    else:
        plan = plan_run(scenario, law=law, artifact=artifact, plant=plant)
    if scenario.model_twin:
        start = twin_start(plant, sigma=plan.sigma0)
    elif like is not None and not like.scenario.model_twin and plan.t is like.plan.t:  # its plan: the same sigma
        start = like.start
    else:
        start = TwinStart({}, False, plan.sigma0)
    return Run(scenario, law=law, artifact=artifact, plant=plant, plan=plan, source=source, start=start,
               record=record, like=like)  # fmt: skip


class Run:
    """One run being made: the loop and its endpoint, then the result.

    ``like``: a run of the same law and artifact (a campaign block's first) whose safe command this run takes, and
    its fault injector too when neither injects a fault (an injector without faults is never changed)."""

    def __init__(self, scenario: Scenario, *, law, artifact: Artifact, plant: Plant, plan: Plan, source: str,
                 start: TwinStart, record: bool = True, like: Run | None = None) -> None:  # fmt: skip
        self.scenario, self.law, self.a, self.plant, self.plan = scenario, law, artifact, plant, plan
        self.source, self.start = source, start
        self.rec = Recorder(plan, artifact=artifact, plant=plant, allocate=record)
        if like is not None and not scenario.faults and not like.scenario.faults:
            self.injector = like.injector
        else:
            self.injector = FaultInjector(scenario.faults, Ts=artifact.Ts, seed=scenario.seed)
        self.safe = law.safe_command(artifact) if like is None else like.safe
        self.extra: dict[str, Any] = {}  # metrics the endpoint adds (the peer's exit, CPU placement, ...)
        self.info: dict[str, Any] = {}

    def _loop(self, endpoint: Any) -> ClosedLoop:
        sc = self.scenario
        return ClosedLoop(plan=self.plan, plant=self.plant, endpoint=endpoint, injector=self.injector, Ts=self.a.Ts,
                          record_state=sc.twin, skip_overruns=sc.overrun == "skip")  # fmt: skip

    def in_process(self, *, library: Path | None, progress) -> Outcome:
        """SIL: the law's float64 reference or its host C, stepped in this process."""
        law, a = self.law, self.a
        controller = law.reference(a) if self.scenario.controller == "reference" else law.native(a, library=library)
        self.endpoint = InProcess(controller, recorder=self.rec, safe_command=self.safe)
        self.info = {"transport": {"kind": "sil (in-process, no link)"}, "controller": self.endpoint.describe}
        self.ran = None if self.scenario.controller == "reference" else law.label
        with gc_paused():
            return self._loop(self.endpoint).run(progress)

    def over_link(self, stack: ExitStack, *, progress) -> Outcome:
        """HIL: the peer behind the scenario's transport, under the run's CPU placement and real-time settings."""
        sc, a = self.scenario, self.a
        transport = transport_from_config(sc.transport, artifact=a)
        peer = start_peer(sc, artifact=a, transport=transport, stack=stack)
        like = "reference" if sc.controller == "reference" else "model"
        self.endpoint = OverLink(transport=transport, peer=peer, recorder=self.rec, injector=self.injector,
                                 plan=self.plan, safe_command=self.safe, step_timeout=sc.step_timeout,
                                 peer_timeout=sc.peer_timeout, Ts=a.Ts,
                                 shadow=self.law.shadow(a, like=like))  # fmt: skip
        placement = stack.enter_context(_placement(sc, peer))
        stack.enter_context(gc_paused())
        realtime = sc.mode == "realtime"
        pm_qos = stack.enter_context(cpu_latency_qos()) if realtime and sc.pm_qos else False
        fifo = _enter_fifo(sc, peer) if realtime else False
        try:
            outcome = self._loop(self.endpoint).run(progress)
        finally:
            if fifo:
                set_other()
        if sc.controller == "qemu":
            transport.close()  # the UART's client leaves before the board powers off (slcan's close writes to it)
        code = peer.stop()  # its exit summary counts everything it received, hostile traffic included
        self.extra = {"controller": {"exit_status": code, "counters": peer.counters(),
                                     "stderr_bytes": peer.stderr_bytes()},
                      "cpu": placement.describe(), "sched_fifo": fifo}  # fmt: skip
        if realtime:
            self.extra["pm_qos"] = pm_qos
        self.info = {"transport": transport.describe(), "controller": _describe_peer(sc, peer)}
        self.ran = None if sc.controller == "reference" else _law_named(peer.ready_line)
        return outcome

    def trace(self, steps: int, *, twins) -> RunTrace:
        """The run's trace up to ``steps``, with its twins."""
        return self.rec.trace(steps, law=self.law, artifact=self.a, twins=twins)

    def result(self, outcome: Outcome, *, twins, twins_s: float, timed: dict | None = None,
               artifact_info: dict | None = None, plant_info: dict | None = None, trace: RunTrace | None = None,
               metrics: dict | None = None) -> RunResult:  # fmt: skip
        """Metrics, trace and what ran, for the steps taken. A campaign block gives what it computed for its runs
        together: ``timed`` (:func:`~.metrics.timing` of this run's steps), ``artifact_info``
        (:func:`~.plan.describe_artifact`), ``plant_info`` (:func:`~.plan.describe_plant` of a plant like this
        run's), the run's ``trace`` (:meth:`trace`) and its ``metrics`` (:func:`~.block_metrics.block_metrics`:
        :func:`~.metrics.compute_metrics`' figures, a new dict)."""
        sc, a, law, steps = self.scenario, self.a, self.law, outcome.steps
        if trace is None:
            trace = self.trace(steps, twins=twins)
        link = isinstance(self.endpoint, OverLink)
        mode = sc.mode if link else "sil"
        late = self.endpoint.late if link else 0
        if metrics is None:
            metrics = compute_metrics(trace, artifact=a, mode=mode, late=late, period_s=self.plan.period_s,
                                      model_start=twins.model_note, timed=timed)  # fmt: skip
        faults = dict(self.injector.counts) if link else {k: v for k, v in self.injector.counts.items() if k == "nan"}
        metrics.update({"complete": outcome.reason is None, "steps_planned": self.plan.N, "wall_s": outcome.wall_s,
                        "steps_per_s": steps / outcome.wall_s if outcome.wall_s > 0 else None, "sched_fifo": False,
                        "faults_injected": faults, "mode": mode, "twins_wall_s": twins_s,
                        "loop_cpu_s": outcome.cpu_s})  # fmt: skip
        metrics.update(self.extra)
        metrics.update(twins.notes)
        if link and sc.mode == "realtime":
            metrics["overruns"], metrics["overrun_policy"] = outcome.overruns, sc.overrun
        if outcome.reason:
            metrics["reason"] = outcome.reason
        if link:
            clipped = self.info["transport"].get("encoding_clipped")
            if clipped is not None:
                metrics["encoding_clipped"] = clipped
            if sc.controller == "qemu":
                metrics["uart"] = link_capacity(self.rec.SENT[:steps], self.rec.BACK[:steps],
                                                answered_in_time=trace.got)  # fmt: skip
        metrics.update(law.run_report(a, trace, ran=self.ran, design_model=is_design_model(sc)))
        if artifact_info is None:
            artifact_info = describe_artifact(law, a, self.source)
        if plant_info is None:
            plant_info = describe_plant(self.plant)
        info = {"artifact": artifact_info, "plant": plant_info, **self.info}
        return RunResult(scenario=sc, metrics=metrics, trace=trace, complete=outcome.reason is None,
                         reason=outcome.reason, info=info, artifact=a)  # fmt: skip


def _law_named(ready_line: str) -> str:
    """The law a node's ready line names (``law=``), ``float32`` when it names none."""
    import re

    m = re.search(r"\blaw=([\w-]+)", ready_line)
    return m.group(1) if m else "float32"


def _describe_peer(scenario: Scenario, peer: Any) -> dict:
    """What the report says about the peer: its kind, command line and ready line, the gain set it said it runs,
    the board of an image."""
    from gainlink.firmware.uart import gains_of

    out: dict[str, Any] = {"kind": scenario.controller, "argv": peer.argv, "ready": peer.ready_line}
    gains = gains_of(peer.ready_line)
    if gains is not None:  # the set the node said it runs (a MAVLink node: always the artifact's, checked at start)
        out["gains"] = gains
    if scenario.controller == "qemu":
        out["board"] = scenario.board
    return out


def _placement(scenario: Scenario, peer: Any) -> Placement:
    """The run's CPU placement of this process and the peer (``affinity``; QEMU's threads: the kernel's)."""
    busy_poll = bool(scenario.transport.get("busy_poll_us", 0))
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
    affinity = "none" if scenario.controller == "qemu" and scenario.affinity == "auto" else scenario.affinity
    setting = resolve_affinity(affinity, mode=scenario.mode, busy_poll=busy_poll, cpus=cpus)
    return Placement(setting, peer_pid=peer.proc.pid if peer.proc is not None else None)


def _enter_fifo(scenario: Scenario, peer: Any) -> bool:
    """SCHED_FIFO for this process and a host peer, when the scenario asks and the system permits."""
    if not scenario.sched_fifo:
        return False
    fifo = set_fifo()
    if fifo and peer.proc is not None and scenario.controller != "qemu":
        set_fifo(peer.proc.pid)  # QEMU's threads stay SCHED_OTHER: its vCPU must not starve its I/O thread
    return fifo


def start_peer(scenario: Scenario, *, artifact: Artifact, transport: Any, stack: ExitStack) -> Any:
    """Open the link and start the controller peer, in the order the link needs; both are closed by ``stack``.

    A host process connects to a link the bridge has opened; the image in QEMU serves its UART, so QEMU starts
    (and prints its banner) before the bridge connects. The Python reference node reads the artifact from a file,
    written once for it.
    """
    if scenario.controller == "qemu":
        peer = qemu_peer(artifact=artifact, transport=transport, board=scenario.board, elf=scenario.firmware,
                         duration_s=scenario.duration)  # fmt: skip
        stack.callback(peer.close)
        peer.start()
        peer.check_artifact(artifact.sha256)
        transport.open()
        stack.callback(transport.close)
        return peer
    path = scenario.artifact_path
    if scenario.controller == "reference":
        folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="gainlink-peer-")))
        path = folder / "gains.json"
        artifact.save(path)
    argv = controller_argv(scenario.controller, artifact=artifact, artifact_path=path, transport=transport,
                           executable=scenario.firmware)  # fmt: skip
    transport.open()
    stack.callback(transport.close)
    peer = ControllerProcess(argv)
    stack.callback(peer.close)
    peer.start()
    peer.check_artifact(artifact.sha256)
    return peer
