"""What a closed-loop run feeds its plant and controller, fixed before the first step, and the per-step
record it fills: shared by the HIL bridge (:mod:`.bridge`) and the in-process SIL loop (:mod:`.sil`),
so both produce the same :class:`~.metrics.RunTrace` from the same scenario and seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gainlink.proof.twin import TwinLoop
from gainlink.shipping.artifact import Artifact

from ..plants.base import Plant
from .metrics import RunTrace
from .scenario import Scenario, profile_values
from .scenario_plant import build_plant


@dataclass(frozen=True)
class Plan:
    """Everything a run feeds the plant and the link, fixed before the first step."""

    N: int
    t: np.ndarray
    R: np.ndarray  # references (N, q)
    noise: np.ndarray  # measurement noise (N, p)
    D: np.ndarray  # input disturbances (N, m)
    silent_at: int | None
    crash_at: int | None
    period_s: float
    realtime: bool


def plan_run(scenario: Scenario, *, artifact: Artifact, plant: Plant, r_op: np.ndarray | None = None) -> Plan:
    """References, noise (from the scenario's seed), disturbances and peer faults per step; a reference without a
    profile holds ``r_op`` (default: the artifact's, which a scheduled artifact gives per point)."""
    a = artifact
    r_op = a.r_op if r_op is None else np.asarray(r_op, dtype=float)
    Ts = a.Ts
    N = int(round(scenario.duration / Ts))
    realtime = scenario.mode == "realtime"
    rng = np.random.default_rng(scenario.seed)
    t = np.arange(N) * Ts
    R = np.tile(r_op, (N, 1))  # absolute: the trim unless a profile says otherwise
    for j, name in enumerate(a.signals["references"]):
        if name in scenario.reference:
            R[:, j] = profile_values(scenario.reference[name], t, base=float(r_op[j]))
    noise_sd = np.array([scenario.noise.get(name, 0.0) for name in plant.output_names])
    noise = rng.standard_normal((N, a.p)) * noise_sd if noise_sd.any() else np.zeros((N, a.p))
    D = np.zeros((N, a.m))
    for d in scenario.disturbances:
        D[(t >= d.start) & (t < d.stop), plant.input_names.index(d.input)] += d.value
    silent_at = min((int(round(f.start / Ts)) for f in scenario.faults if f.kind == "silent"), default=None)
    crash_at = min((int(round(f.start / Ts)) for f in scenario.faults if f.kind == "crash"), default=None)
    period = scenario.period if (realtime and scenario.period) else Ts
    return Plan(
        N=N, t=t, R=R, noise=noise, D=D, silent_at=silent_at, crash_at=crash_at, period_s=period, realtime=realtime
    )


class Recorder:
    """The per-step arrays of a run, filled as it goes; :meth:`trace` cuts them to the steps taken."""

    def __init__(self, plan: Plan, *, artifact: Artifact, plant: Plant) -> None:
        N, a = plan.N, artifact
        self.plan = plan
        self.Y = np.zeros((N, a.p))
        self.U = np.zeros((N, a.m))
        self.SAT = np.zeros((N, a.m), dtype=bool)
        self.GOT = np.zeros(N, dtype=bool)
        self.LAT = np.full(N, np.nan)
        self.SENT = np.full(N, np.nan)  # when sample k was sent, ns from the run start (NaN: never sent)
        self.BACK = np.full(N, np.nan)  # when its command came back, in time or late (NaN: never)
        self.TICK = np.zeros(N)
        self.DUE = np.full(N, np.nan)
        self.ST = np.zeros(N, dtype=np.int64)
        self.X = np.full((N, len(plant.state_names)), np.nan)

    def trace(self, steps: int, twin: TwinLoop | None = None, model: TwinLoop | None = None) -> RunTrace:
        """The recorded run up to ``steps``, with the twin's (NaN without one) and the model twin's (None)."""
        p = self.plan
        tw = twin.trace(steps) if twin is not None else None
        mt = model.trace(steps) if model is not None else None

        def nan(width: int) -> np.ndarray:
            return np.full((steps, width), np.nan)

        return RunTrace(
            t=p.t[:steps],
            y=self.Y[:steps],
            r=p.R[:steps],
            u=self.U[:steps],
            sat=self.SAT[:steps],
            got=self.GOT[:steps],
            latency_ns=self.LAT[:steps],
            tick_ns=self.TICK[:steps],
            deadline_ns=self.DUE[:steps],
            x=self.X[:steps],
            status=self.ST[:steps],
            twin_y=tw.y if tw else nan(self.Y.shape[1]),
            twin_u=tw.u if tw else nan(self.U.shape[1]),
            twin_z=tw.z if tw else nan(p.R.shape[1]),
            model_y=mt.y if mt else None,
            model_u=mt.u if mt else None,
        )


def describe_artifact(artifact: Artifact, path) -> dict:
    """What a report says about the artifact: identity, the compensator's stability and, for a model
    ``linearize`` wrote, the interface it was checked through and its fit (from the provenance)."""
    from gainlink.synthesis.compensator import compensator_stability

    comp = compensator_stability(artifact)
    out = {
        "name": artifact.name,
        "sha256": artifact.sha256,
        "path": str(path),
        "compensator": {**comp.to_dict(), "summary": comp.describe()},
    }
    model = {k: artifact.provenance[k] for k in ("plant_interface", "plant_fit") if k in artifact.provenance}
    if model:
        out["model"] = model
    if artifact.signals.get("units"):  # for the summary's figures (what the spec said each signal is measured in)
        out["units"] = dict(artifact.signals["units"])
    return out


def describe_plant(plant: Plant) -> dict:
    """What a report says about the plant: its signals and, for an FMU, the interface that ran and why."""
    from ..plants.fmu_interface import describe_interface

    return {
        "name": plant.name,
        "inputs": list(plant.input_names),
        "outputs": list(plant.output_names),
        "states": list(plant.state_names),
        **describe_interface(plant),
    }


def start_model_twin(
    scenario: Scenario, *, artifact: Artifact, plan: Plan, plant: Plant
) -> tuple[TwinLoop | None, str]:
    """The run's model twin (:mod:`.model_twin`) started where ``plant`` (just reset) is, and a note on where
    that is; (None, "") when ``scenario.model_twin`` is off."""
    if not scenario.model_twin:
        return None, ""
    from .model_twin import start_model_twin as start

    return start(artifact, plant=plant, steps=plan.N)


def step_twins(twins: tuple, k: int, plan: Plan) -> None:
    """Advance the run's twins (those that run) through sample ``k``: same noise, reference and disturbance."""
    for twin in twins:
        if twin is not None:
            twin.step(k, noise=plan.noise[k], r=plan.R[k], d=plan.D[k])


def start_twin(scenario: Scenario, *, artifact: Artifact, plan: Plan, stack) -> TwinLoop | None:
    """The run's float64 twin (:mod:`gainlink.proof.twin`) on a second instance of the scenario's plant (a second
    FMU instance), reset to the same initial state; None when ``scenario.twin`` is off.

    The plant is closed by ``stack`` (an :class:`contextlib.ExitStack`).
    """
    if not scenario.twin:
        return None
    plant = build_plant(scenario, artifact=artifact)
    stack.callback(plant.close)
    plant.reset(initial=scenario.initial_state)
    return TwinLoop(artifact, outputs=plant.outputs, advance=lambda u: plant.advance(u=u, dt=artifact.Ts), steps=plan.N)
