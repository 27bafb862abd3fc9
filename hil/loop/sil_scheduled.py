"""Software in the loop for a scheduled artifact (schema 2): :func:`~.sil.run_sil` hands it here.

Per step the plant is sampled (plus noise), sigma comes from the measured output the schedule names or, when it
is an external signal, from the scenario's ``[schedule_signal.NAME]`` profile, the scheduled law computes the
command — the float64 reference (``controller = "reference"``) or the scheduled C of the host library through
ctypes (``firmware``) — and the plant advances under it for one ``Ts``. The trace records sigma and its flags per
step; the report's ``schedule`` block (:mod:`.sched_metrics`) the range sigma covered. The closed-loop twin runs
the float64 scheduled law on a second instance of the plant, the model twin the same law around the design's model
at the sigma it runs at (:mod:`.sched_law`). A plant with a ``schedule(s)`` method (``kind = "scheduled_model"``)
is handed the external signals before each sample: its dynamics follow them.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path

import numpy as np
from gainlink.errors import PlantError, ScenarioError
from gainlink.shipping.artifact import Artifact

from ..plants.base import Plant
from .bridge import RunResult
from .metrics import compute_metrics
from .plan import Plan, Recorder, describe_plant, plan_run
from .scenario import Scenario, profile_values
from .scenario_plant import build_plant
from .sched_law import NativeScheduled, ReferenceScheduled, ScheduledTwin, start_scheduled_model_twin


def external_signals(scenario: Scenario, *, artifact: Artifact, t: np.ndarray) -> np.ndarray:
    """The external scheduling signals per step (N, e) from ``[schedule_signal.NAME]``; one line when one is
    missing or a profile names no external signal of the artifact."""
    names = artifact.schedule.external
    for name in scenario.schedule_signal:
        if name not in names:
            raise ScenarioError(
                f"scenario: schedule_signal.{name} is not an external scheduling signal of the artifact "
                f"(external: {', '.join(names) or 'none'}; sigma {artifact.schedule.sigma} is a measured output)"
            )
    missing = [n for n in names if n not in scenario.schedule_signal]
    if missing:
        raise ScenarioError(f"scenario: the artifact is scheduled on {', '.join(missing)}: give [schedule_signal.NAME]")
    return np.column_stack([profile_values(scenario.schedule_signal[n], t) for n in names] or [np.zeros((t.size, 0))])


def start_sigma(artifact: Artifact, *, plant: Plant, S: np.ndarray) -> float:
    """Where sigma starts: the schedule's output at the plant's reset state, or the external signal at t = 0,
    clipped into the envelope."""
    sch = artifact.schedule
    raw = plant.outputs()[sch.index] if sch.source == "output" else (S[0, sch.index] if S.shape[0] else sch.points[0])
    return sch.clip(float(raw))


def describe_scheduled(artifact: Artifact, path) -> dict:
    """What a report says about a scheduled artifact: identity and its schedule."""
    S = artifact.schedule
    out = {
        "name": artifact.name,
        "sha256": artifact.sha256,
        "path": str(path),
        "schedule": {
            "sigma": S.sigma,
            "source": S.source,
            "points": [float(v) for v in S.points],
            "rate_max": S.rate_max,
            "rate_certified": S.rate_certified,
            "filter_tau": S.filter_tau,
        },
    }
    removed = artifact.data.get("provenance", {}).get("rate_limit_removed")
    if removed:  # sigma_rate_limit = false: the law runs without the designed rate_max
        out["rate_limit_removed"] = removed
    if artifact.signals.get("units"):
        out["units"] = dict(artifact.signals["units"])
    return out


def without_rate_limit(artifact: Artifact) -> Artifact:
    """A copy of a scheduled artifact whose law does not limit sigma's rate (``rate_max`` removed, re-sealed; its
    provenance's ``rate_limit_removed`` says which ``rate_max`` of which artifact): the scenario's
    ``sigma_rate_limit = false``. No certificate covers an unlimited rate unless one covered any rate already."""
    from gainlink.shipping.artifact import from_dict, seal

    S = artifact.schedule
    certified = S.rate_certified and S.rate_max is None
    data = dict(artifact.data, schedule=dict(artifact.data["schedule"], rate_max=None, rate_certified=certified))
    removed = f"rate_max {artifact.schedule.rate_max!r} of sha256:{artifact.sha256}"
    data["provenance"] = dict(data.get("provenance", {}), rate_limit_removed=removed)
    return from_dict(seal(data))


def run_scheduled_sil(
    artifact: Artifact,
    scenario: Scenario,
    *,
    library: Path | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RunResult:
    """Run ``scenario`` with the scheduled law of ``artifact`` in this process (module docstring); the arguments
    are :func:`~.sil.run_sil`'s, already checked."""
    if scenario.controller not in ("firmware", "reference"):
        raise ScenarioError(
            f'scenario {scenario.name}: a scheduled artifact runs as SIL with controller = "firmware" (the host C) '
            f'or "reference", not "{scenario.controller}"'
        )
    if not scenario.sigma_rate_limit:  # another artifact: a library built for the given one does not serve it
        artifact, library = without_rate_limit(artifact), None
    plant = build_plant(scenario, artifact=artifact)
    with ExitStack() as stack:
        stack.callback(plant.close)
        reference = scenario.controller == "reference"
        law = ReferenceScheduled(artifact) if reference else NativeScheduled(artifact, library=library)
        loop = _ScheduledSil(artifact, scenario, plant=plant, law=law)
        if scenario.twin:
            loop.twin = _closed_loop_twin(scenario, artifact=artifact, steps=loop.plan.N, stack=stack)
        return loop.run(progress)


def _closed_loop_twin(scenario: Scenario, *, artifact: Artifact, steps: int, stack: ExitStack) -> ScheduledTwin:
    """The float64 scheduled law on a second instance of the scenario's plant, reset to the same state."""
    plant = build_plant(scenario, artifact=artifact)
    stack.callback(plant.close)
    plant.reset(initial=scenario.initial_state)
    return ScheduledTwin(artifact, outputs=plant.outputs, advance=lambda u: plant.advance(u=u, dt=artifact.Ts),
                         steps=steps, on_signals=getattr(plant, "schedule", None))  # fmt: skip


class _ScheduledSil:
    """One scheduled SIL run, step by step: sample, law step (sigma with it), advance."""

    def __init__(self, artifact: Artifact, scenario: Scenario, *, plant: Plant, law) -> None:
        self.a, self.scenario, self.plant, self.law = artifact, scenario, plant, law
        plant.reset(initial=scenario.initial_state)
        N = int(round(scenario.duration / artifact.Ts))
        self.S = external_signals(scenario, artifact=artifact, t=np.arange(N) * artifact.Ts)
        if N and hasattr(plant, "schedule"):
            plant.schedule(self.S[0])
        self.sigma0 = start_sigma(artifact, plant=plant, S=self.S)
        r_op = artifact.Ci @ artifact.schedule.trim_at(self.sigma0)[1]
        self.plan: Plan = plan_run(scenario, artifact=artifact, plant=plant, r_op=r_op)
        self.rec = Recorder(self.plan, artifact=artifact, plant=plant)
        self.SIG, self.FLAGS = np.zeros(N), np.zeros(N, dtype=np.int64)
        self.twin: ScheduledTwin | None = None
        self.model_twin, self.model_start = None, ""
        self.bits = np.arange(artifact.m, dtype=np.uint32)
        self.follows = getattr(plant, "schedule", None)  # a plant whose dynamics follow the external signals
        self.mode = "sil"  # the timing compute_metrics reads (realtime: ticks against their deadlines)

    def run(self, progress: Callable[[int, int], None] | None) -> RunResult:
        """Every planned step, or until the plant fails."""
        N, reason, k = self.plan.N, None, 0
        if self.scenario.model_twin:
            self.model_twin, self.model_start = start_scheduled_model_twin(
                self.a, plant=self.plant, steps=N, sigma0=self.sigma0
            )
        every = max(1, N // 100)
        self.t_start = time.perf_counter_ns()
        try:
            while k < N:
                k = self._tick(k)
                if k >= N:
                    break
                self._step(k)
                k += 1
                if progress is not None and k % every == 0:
                    progress(k, N)
            k = N
        except PlantError as exc:
            reason = f"plant failed at step {k}: {exc}"
            k += 1
        wall = (time.perf_counter_ns() - self.t_start) / 1e9
        return self._result(k, reason=reason, wall=wall)

    def _tick(self, k: int) -> int:
        """The step to run next, from ``k`` (a paced run waits for it here)."""
        return k

    def _step(self, k: int) -> None:
        rec, plan = self.rec, self.plan
        if self.follows is not None:
            self.follows(self.S[k])
        y = self.plant.outputs() + plan.noise[k]
        rec.Y[k] = y
        if self.twin is not None:
            rec.X[k] = self.plant.state()
        t0 = time.perf_counter_ns()
        out = self.law.step(y, plan.R[k], self.S[k])
        t1 = time.perf_counter_ns()
        rec.GOT[k], rec.LAT[k], rec.TICK[k], rec.ST[k] = True, t1 - t0, t0 - self.t_start, out.status
        rec.SAT[k] = ((out.sat_mask >> self.bits) & 1).astype(bool)
        rec.U[k], self.SIG[k], self.FLAGS[k] = out.u, out.sigma, out.sigma_flags
        try:
            self.plant.advance(u=np.asarray(out.u, float) + plan.D[k], dt=self.a.Ts)
        finally:
            for twin in (self.twin, self.model_twin):
                if twin is not None:
                    twin.step(k, noise=plan.noise[k], r=plan.R[k], d=plan.D[k], s=self.S[k])

    def _result(self, steps: int, *, reason: str | None, wall: float) -> RunResult:
        a, scenario = self.a, self.scenario
        trace = self.rec.trace(steps, self.twin, self.model_twin)
        trace = dataclasses.replace(trace, sigma=self.SIG[:steps].copy(), sigma_flags=self.FLAGS[:steps].copy())
        metrics = compute_metrics(trace, artifact=a, mode=self.mode, late=0, period_s=self.plan.period_s,
                                  model_start=self.model_start)  # fmt: skip
        metrics.update({"complete": reason is None, "steps_planned": self.plan.N, "wall_s": wall,
                        "steps_per_s": steps / wall if wall > 0 else None, "sched_fifo": False,
                        "faults_injected": {}, "mode": "sil"})  # fmt: skip
        if reason:
            metrics["reason"] = reason
        if self.scenario.model_twin and self.model_twin is None:
            metrics["model_twin_off"] = self.model_start
        info = {
            "artifact": describe_scheduled(a, scenario.artifact_path),
            "plant": describe_plant(self.plant),
            "transport": {"kind": "sil (in-process, no link)"},
            "controller": self.law.kind,
        }
        return RunResult(
            scenario=scenario, metrics=metrics, trace=trace, complete=reason is None, reason=reason, info=info
        )
