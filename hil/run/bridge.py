"""The HIL bridge: plant on this side, controller peer on the other side of a transport.

:func:`run_scenario` builds the plant and the transport from the scenario, starts the controller
process, runs the loop in lockstep (the plant waits for each command, up to ``step_timeout``) or in
real time (fixed period, sleep-then-spin to absolute deadlines, SCHED_FIFO and a 0 us CPU wake-up
latency request when permitted), and always stops the peer. A peer that dies, or stays silent for ``peer_timeout``, ends the run early
with ``complete = False`` and the reason.
"""

from __future__ import annotations

import logging
import os
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from gainlink.artifact import Artifact, load
from gainlink.errors import GainlinkError, PlantError, ScenarioError
from gainlink.reference import ReferenceLoop

from .controller import ControllerProcess, controller_argv
from .faults import FaultInjector
from ..plants.fmu import plant_from_config
from .metrics import RunTrace, compute_metrics
from ..plants.base import Plant, check_dimensions
from .scheduler import SPIN_NS, Pacer, Placement, cpu_latency_qos, gc_paused, resolve_affinity, set_fifo, set_other
from .scenario import Scenario, profile_values
from ..links.base import Transport, transport_from_config

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
    base = scenario.path.parent if scenario.path is not None else Path.cwd()
    plant = plant_from_config(scenario.plant, artifact=artifact, base_dir=base)
    try:
        check_dimensions(plant, m=artifact.m, p=artifact.p, artifact=str(scenario.artifact_path))
        for name in scenario.reference:
            if name not in artifact.signals["references"]:
                raise ScenarioError(f"scenario: reference {name!r} is not a reference of the artifact "
                                    f"(references: {', '.join(artifact.signals['references']) or 'none'})")
        for name in scenario.noise:
            if name not in plant.output_names:
                raise ScenarioError(f"scenario: noise on {name!r}, which is not a plant output "
                                    f"({', '.join(plant.output_names)})")
        for d in scenario.disturbances:
            if d.input not in plant.input_names:
                raise ScenarioError(f"scenario: disturbance on {d.input!r}, which is not a plant input "
                                    f"({', '.join(plant.input_names)})")
    except GainlinkError:
        plant.close()
        raise
    return artifact, plant


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
    artifact, plant = prepare(scenario)
    with ExitStack() as stack:
        stack.callback(plant.close)
        transport = transport_from_config(scenario.transport, artifact=artifact)
        argv = controller_argv(scenario.controller, artifact=artifact, artifact_path=scenario.artifact_path,
                               transport=transport, executable=scenario.firmware)
        transport.open()
        stack.callback(transport.close)
        peer = ControllerProcess(argv)
        stack.callback(peer.close)
        peer.start()
        peer.check_artifact(artifact.sha256)
        busy_poll = bool(scenario.transport.get("busy_poll_us", 0))
        cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
        placement = stack.enter_context(Placement(
            resolve_affinity(scenario.affinity, mode=scenario.mode, busy_poll=busy_poll, cpus=cpus),
            peer_pid=peer.proc.pid if peer.proc is not None else None))
        stack.enter_context(gc_paused())
        pm_qos = stack.enter_context(cpu_latency_qos()) if scenario.mode == "realtime" and scenario.pm_qos else False
        result = _loop(scenario, artifact=artifact, plant=plant, transport=transport, peer=peer, progress=progress)
        result.metrics["cpu"] = placement.describe()
        if scenario.mode == "realtime":
            result.metrics["pm_qos"] = pm_qos
        clipped = result.info["transport"].get("encoding_clipped")
        if clipped is not None:
            result.metrics["encoding_clipped"] = clipped
        return result


def _loop(scenario: Scenario, *, artifact: Artifact, plant: Plant, transport: Transport, peer: ControllerProcess,
          progress: Callable[[int, int], None] | None) -> RunResult:
    a = artifact
    Ts = a.Ts
    N = int(round(scenario.duration / Ts))
    realtime = scenario.mode == "realtime"
    period = scenario.period if (realtime and scenario.period) else Ts
    period_ns = int(round(period * 1e9))
    rng = np.random.default_rng(scenario.seed)
    t = np.arange(N) * Ts
    R = np.zeros((N, a.q))
    for j, name in enumerate(a.signals["references"]):
        if name in scenario.reference:
            R[:, j] = profile_values(scenario.reference[name], t)
    noise_sd = np.array([scenario.noise.get(name, 0.0) for name in plant.output_names])
    noise = rng.standard_normal((N, a.p)) * noise_sd if noise_sd.any() else np.zeros((N, a.p))
    D = np.zeros((N, a.m))
    for d in scenario.disturbances:
        D[(t >= d.start) & (t < d.stop), plant.input_names.index(d.input)] += d.value
    silent_at = min((int(round(f.start / Ts)) for f in scenario.faults if f.kind == "silent"), default=None)
    crash_at = min((int(round(f.start / Ts)) for f in scenario.faults if f.kind == "crash"), default=None)
    injector = FaultInjector(scenario.faults, Ts=Ts)
    shadow = ReferenceLoop(a) if scenario.shadow else None

    Y = np.zeros((N, a.p)); U = np.zeros((N, a.m)); SAT = np.zeros((N, a.m), dtype=bool)
    GOT = np.zeros(N, dtype=bool); LAT = np.full(N, np.nan); TICK = np.zeros(N); DUE = np.full(N, np.nan)
    UREF = np.full((N, a.m), np.nan); ZREF = np.full((N, a.q), np.nan); ST = np.zeros(N, dtype=np.int64)
    X = np.full((N, len(plant.state_names)), np.nan)
    record_states = scenario.shadow  # the plant state costs an FMU call per step: only with the shadow on

    plant.reset(initial=scenario.initial_state)
    u = np.clip(np.zeros(a.m), a.u_min, a.u_max)
    late = 0
    silent_since_ns: int | None = None
    complete, reason = True, None
    fifo = False
    seq_mod = transport.seq_modulo
    if realtime and scenario.sched_fifo:
        fifo = set_fifo()
        if fifo and peer.proc is not None:
            set_fifo(peer.proc.pid)
    every = max(1, N // 100)
    skip = scenario.overrun == "skip"
    overruns = 0
    t_start = time.perf_counter_ns()
    pacer = Pacer(period_ns=period_ns)
    k = 0
    try:
        while k < N:
            if silent_at is not None and k >= silent_at:
                peer.pause()
                silent_at = None
            if crash_at is not None and k >= crash_at:
                peer.kill()
                crash_at = None
            if realtime:
                tick, due_rel, woke_rel = pacer.wait_next(skip=skip)
                offset = pacer.start_ns - t_start
                if tick > k:  # overrun: these ticks passed while the bridge was stalled; the plant ran on
                    for j in range(k, min(tick, N)):  # under the held command, as a real one would
                        Y[j] = plant.outputs() + noise[j]
                        U[j] = u
                        DUE[j] = due_rel - (tick - j) * period_ns + offset
                        TICK[j] = np.nan  # never ran: no jitter, a miss
                        plant.advance(u=u + D[j], dt=Ts)
                    overruns += min(tick, N) - k
                    k = min(tick, N)
                    if k >= N:
                        break
                DUE[k] = due_rel + offset
                woke = woke_rel + offset
                wait_until = pacer.start_ns + due_rel + period_ns - SPIN_NS // 2
            y = plant.outputs() + noise[k]
            Y[k] = y
            if record_states:
                X[k] = plant.state()
            seq = k % seq_mod
            frames = injector.apply(k, transport.encode_sample(seq=seq, y=y, r=R[k]))
            sent = time.perf_counter_ns()
            TICK[k] = woke if realtime else sent - t_start
            transport.send_frames(frames)
            if shadow is not None:
                res = shadow.step(*transport.received_sample(y=y, r=R[k]))
                UREF[k] = res.u
                ZREF[k] = shadow.z
            deadline = wait_until if realtime else sent + int(scenario.step_timeout * 1e9)
            cmd = None
            while True:
                left = (deadline - time.perf_counter_ns()) / 1e9
                if left <= 0:
                    break
                c = transport.receive_command(timeout=left)
                if c is None:
                    break
                if c.seq == seq:
                    cmd = c
                    break
                late += 1
            if cmd is not None:
                u = cmd.u
                GOT[k] = True
                LAT[k] = cmd.t_ns - sent
                SAT[k] = cmd.saturated
                ST[k] = cmd.status
                silent_since_ns = None
            else:
                now = time.perf_counter_ns()
                silent_since_ns = silent_since_ns or sent
                code = peer.exit_status()
                if code is not None:
                    complete, reason = False, (f"controller exited with status {code} at step {k} "
                                               f"(t={k * Ts:.3f} s){_tail(peer)}")
                    U[k] = u
                    k += 1
                    break
                if now - silent_since_ns >= scenario.peer_timeout * 1e9:
                    complete, reason = False, (f"controller silent for {scenario.peer_timeout:g} s since step "
                                               f"{int(round((silent_since_ns - t_start) / 1e9 / max(period, 1e-9)))}"
                                               f" (no command for sample {k}, t={k * Ts:.3f} s)")
                    U[k] = u
                    k += 1
                    break
            U[k] = u
            try:
                plant.advance(u=u + D[k], dt=Ts)
            except PlantError as exc:
                complete, reason = False, f"plant failed at step {k}: {exc}"
                k += 1
                break
            k += 1
            if progress is not None and k % every == 0:
                progress(k, N)
    except PlantError as exc:  # in an overrun's held steps
        complete, reason = False, f"plant failed at step {k}: {exc}"
    finally:
        if fifo:
            set_other()
    steps = k
    trace = RunTrace(t=t[:steps], y=Y[:steps], r=R[:steps], u=U[:steps], sat=SAT[:steps], got=GOT[:steps],
                     latency_ns=LAT[:steps], tick_ns=TICK[:steps], deadline_ns=DUE[:steps], u_ref=UREF[:steps],
                     z_ref=ZREF[:steps], x=X[:steps], status=ST[:steps])
    metrics = compute_metrics(trace, artifact=a, mode=scenario.mode, late=late, period_s=period)
    wall = (time.perf_counter_ns() - t_start) / 1e9
    metrics.update({"complete": complete, "steps_planned": N, "wall_s": wall,
                    "steps_per_s": steps / wall if wall > 0 else None, "sched_fifo": fifo,
                    "faults_injected": injector.counts, "mode": scenario.mode})
    if realtime:
        metrics["overruns"] = overruns
        metrics["overrun_policy"] = scenario.overrun
    if reason:
        metrics["reason"] = reason
    if progress is not None:
        progress(steps, N)
    info = {"artifact": {"name": a.name, "sha256": a.sha256, "path": str(scenario.artifact_path)},
            "plant": {"name": plant.name, "inputs": list(plant.input_names), "outputs": list(plant.output_names),
                      "states": list(plant.state_names)},
            "transport": transport.describe(), "controller": {"kind": scenario.controller, "argv": peer.argv,
                                                              "ready": peer.ready_line}}
    return RunResult(scenario=scenario, metrics=metrics, trace=trace, complete=complete, reason=reason, info=info)


def _tail(peer: ControllerProcess) -> str:
    text = peer.stderr_tail()
    return f": {text}" if text else ""
