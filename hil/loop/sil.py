"""Software in the loop: the host build of the C loop through ctypes against the plant, in this process.

No bus, no peer process, no pacing: per step the plant is sampled (plus the scenario's noise), the C
``gl_loop_step`` computes the command, and the plant advances under it (plus the disturbances) for one
``Ts``. The run is a pure function of (artifact, scenario, seed) and returns the bridge's
:class:`~.bridge.RunResult` with the same :class:`~.metrics.RunTrace` and metrics, so the report, the
closed-loop twin and campaigns treat a SIL run and a HIL run alike. ``latency_us`` is the time of the
C step call itself. With ``controller = "reference"`` the float64 law steps instead of the C.

SIL is what a campaign runs by default: a pendulum run of 1000 steps takes a fraction of a second.
Link faults (drop, delay, ...), a silent or crashed controller and real-time pacing need a HIL run and
are refused with one line. A scheduled artifact runs its scheduled law (:mod:`.sil_scheduled`); a fixed-point
artifact the integer law it certifies (:class:`~gainlink.engines.fixed_native.FixedNativeLoop`: ``gl_fixed_step``),
its report's ``fixed_point`` block checking it bit for bit against the integer model and beside the certified
bounds, as over CAN (:mod:`.can_fixed`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path

import numpy as np
from gainlink.engines.fixed_native import FixedNativeLoop
from gainlink.engines.native import NativeLoop
from gainlink.errors import PlantError, ScenarioError
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping.artifact import Artifact
from gainlink.shipping.codegen_fixed import is_fixed

from .bridge import RunResult, is_design_model
from .can_fixed import fixed_can_check
from .metrics import compute_metrics
from .plan import Recorder, describe_artifact, describe_plant, plan_run, start_model_twin, start_twin, step_twins
from .scenario import Scenario
from .scenario_plant import build_plant

GL_SATURATED, GL_ERR_NANINF = 1, -2


class _ReferenceController:
    """The float64 law behind the same step interface as the C loop (``u``, ``status``, ``sat_mask``)."""

    def __init__(self, artifact: Artifact) -> None:
        self.law = ReferenceLoop(artifact)

    def step(self, y: np.ndarray, r: np.ndarray):
        res = self.law.step(y, r)
        status = GL_ERR_NANINF if res.fault else (GL_SATURATED if res.saturated.any() else 0)
        mask = int(np.sum(res.saturated.astype(int) << np.arange(res.saturated.size)))
        return _Out(u=res.u, status=status, sat_mask=mask)


@dataclasses.dataclass(frozen=True)
class _Out:
    u: np.ndarray
    status: int
    sat_mask: int


def check_sil(scenario: Scenario) -> None:
    """Refuse what only a HIL run can do (link and peer faults, real-time pacing), with one line."""
    if scenario.faults:
        kinds = ", ".join(sorted({f.kind for f in scenario.faults}))
        raise ScenarioError(
            f"scenario {scenario.name}: faults ({kinds}) act on a link or a controller process; "
            "a SIL run has neither (run it as HIL)"
        )
    if scenario.mode == "realtime":
        raise ScenarioError(f'scenario {scenario.name}: a SIL run is not paced; mode = "realtime" needs HIL')


def run_sil(
    artifact: Artifact,
    scenario: Scenario,
    *,
    seed: int | None = None,
    library: Path | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RunResult:
    """Run ``scenario`` with the C loop of ``artifact`` in this process against the scenario's plant.

    Parameters
    ----------
    artifact : Artifact
        The gain artifact (``scenario.artifact_path`` is not read).
    scenario : Scenario
        Plant, duration, references, initial state, noise, disturbances, ``controller`` (``firmware``:
        the C loop; ``reference``: the float64 law) and ``twin`` (the float64 twin of the loop beside it).
        Its transport is not used.
    seed : int, optional
        Noise seed (default: the scenario's).
    library : Path, optional
        A prebuilt ``libgainlink_host.so`` of this artifact (default: built and cached by sha256).
    progress : callable, optional
        Called as ``progress(done, total)`` every hundredth of the run.

    Returns
    -------
    RunResult
        ``complete`` is False, with the reason, when the plant fails (e.g. its state became non-finite).
    """
    if seed is not None:
        scenario = dataclasses.replace(scenario, seed=int(seed))
    check_sil(scenario)
    if artifact.schedule is not None:
        from .sil_scheduled import run_scheduled_sil

        return run_scheduled_sil(artifact, scenario, library=library, progress=progress)
    if scenario.schedule_signal or not scenario.sigma_rate_limit:
        what = "schedule_signal" if scenario.schedule_signal else "sigma_rate_limit"
        raise ScenarioError(f"scenario {scenario.name}: {what} is for a scheduled artifact")
    plant = build_plant(scenario, artifact=artifact)
    with ExitStack() as stack:
        stack.callback(plant.close)
        if scenario.controller == "firmware" and is_fixed(artifact):  # the integer law the artifact certifies
            law = FixedNativeLoop(artifact, library=library)
            kind = {"kind": f"firmware (host C {law.law} fixed-point loop, ctypes)", "library": str(law.library)}
        elif scenario.controller == "firmware":
            law = NativeLoop(artifact, library=library)
            kind = {"kind": "firmware (host C loop, ctypes)", "library": str(law.library)}
        else:
            law = _ReferenceController(artifact)
            kind = {"kind": "reference (float64 law)"}
        loop = _SilLoop(artifact, scenario, plant=plant, law=law)
        loop.twin = start_twin(scenario, artifact=artifact, plan=loop.plan, stack=stack)
        result = loop.run(progress, controller=kind)
    if isinstance(law, FixedNativeLoop):  # the integer law checked against its model and the float64 law
        ready = f"law={law.law}"
        result.metrics["fixed_point"] = fixed_can_check(artifact, result.trace, ready_line=ready,
                                                        model_plant=is_design_model(scenario))  # fmt: skip
    return result


class _SilLoop:
    """One SIL run, step by step: sample, C step, advance."""

    def __init__(self, artifact: Artifact, scenario: Scenario, *, plant, law) -> None:
        self.a, self.scenario, self.plant, self.law = artifact, scenario, plant, law
        self.plan = plan_run(scenario, artifact=artifact, plant=plant)
        self.rec = Recorder(self.plan, artifact=artifact, plant=plant)
        self.twin = None  # the float64 twin (gainlink.proof.twin), set by run_sil when the scenario has one
        self.model_twin, self.model_start = None, ""  # the model twin (.model_twin), started with the run
        self.bits = np.arange(artifact.m, dtype=np.uint32)

    def run(self, progress: Callable[[int, int], None] | None, *, controller: dict) -> RunResult:
        """Every planned step, or until the plant fails."""
        N, reason, k = self.plan.N, None, 0
        self.plant.reset(initial=self.scenario.initial_state)
        self.model_twin, self.model_start = start_model_twin(
            self.scenario, artifact=self.a, plan=self.plan, plant=self.plant
        )
        every = max(1, N // 100)
        t_start = time.perf_counter_ns()
        self.t_start = t_start
        try:
            for k in range(N):
                self._step(k)
                if progress is not None and (k + 1) % every == 0:
                    progress(k + 1, N)
            k = N
        except PlantError as exc:
            reason = f"plant failed at step {k}: {exc}"
            k += 1
        wall = (time.perf_counter_ns() - t_start) / 1e9
        if progress is not None:
            progress(k, N)
        return self._result(k, reason=reason, wall=wall, controller=controller)

    def _step(self, k: int) -> None:
        rec, plan = self.rec, self.plan
        y = self.plant.outputs() + plan.noise[k]
        rec.Y[k] = y
        r = plan.R[k]
        if self.twin is not None:
            rec.X[k] = self.plant.state()
        t0 = time.perf_counter_ns()
        out = self.law.step(y, r)
        t1 = time.perf_counter_ns()
        u = np.asarray(out.u, dtype=float)
        rec.GOT[k], rec.LAT[k], rec.TICK[k], rec.ST[k] = True, t1 - t0, t0 - self.t_start, out.status
        rec.SAT[k] = ((out.sat_mask >> self.bits) & 1).astype(bool)
        rec.U[k] = u
        try:
            self.plant.advance(u=u + plan.D[k], dt=self.a.Ts)
        finally:
            step_twins((self.twin, self.model_twin), k, plan)

    def _result(self, steps: int, *, reason: str | None, wall: float, controller: dict) -> RunResult:
        a, scenario, plant = self.a, self.scenario, self.plant
        trace = self.rec.trace(steps, self.twin, self.model_twin)
        metrics = compute_metrics(trace, artifact=a, mode="sil", late=0, period_s=a.Ts, model_start=self.model_start)
        metrics.update(
            {
                "complete": reason is None,
                "steps_planned": self.plan.N,
                "wall_s": wall,
                "steps_per_s": steps / wall if wall > 0 else None,
                "sched_fifo": False,
                "faults_injected": {},
                "mode": "sil",
            }
        )
        if reason:
            metrics["reason"] = reason
        info = {
            "artifact": describe_artifact(a, scenario.artifact_path),
            "plant": describe_plant(plant),
            "transport": {"kind": "sil (in-process, no link)"},
            "controller": controller,
        }
        return RunResult(
            scenario=scenario, metrics=metrics, trace=trace, complete=reason is None, reason=reason, info=info
        )
