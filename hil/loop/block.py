"""A campaign block: SIL runs of one artifact stepped together, in lockstep, each answering what it answers alone.

Per step ``k`` every run of the block is sampled (its plant's outputs plus its own noise, one stacked array), the law
answers the whole block in one call (:meth:`gainlink.laws.Law.native_block`: one C call for the host C;
:meth:`gainlink.laws.Law.reference_block`: the float64 law, as columns for the lq law) and the plants advance together
(:class:`~..plants.models.OdeBatch`, the RK4 kernel a plant alone steps with a batch of one;
:class:`~..plants.linear.LinearBatch`, each run's own matrices). The closed-loop twin is stepped the same way afterwards
(the float64 reference of each run around a second block of plants). Each run is prepared (plan, noise, references) and
reported (metrics, the law's report) by the very functions a run alone uses (:mod:`.bridge`), so a run's trace and
verdict are the same bit for bit whichever path ran it (timing columns aside: a block times its calls, not a run).

What cannot step so (:func:`refusal`: a link, faults, a plant that is not vectorised, a plant that follows external
signals) is left to the caller, which runs it alone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from gainlink.laws import law_of
from gainlink.shipping.artifact import Artifact

from ..plants.linear import LinearBatch, linear_batchable
from ..plants.models import OdeBatch, batchable, non_finite
from .bridge import Run, RunResult, build_plant, in_process, prepare_run
from .closed_loop import Outcome
from .scenario import Scenario
from .twins import with_model_twin

SIL = {"kind": "sil (in-process, no link)"}  # the run's transport block, as a run alone reports it


def refusal(scenario: Scenario) -> str | None:
    """Why ``scenario`` cannot step in a block (it runs alone), or None."""
    if not in_process(scenario):
        return "it runs over a link (HIL runs one at a time)"
    if scenario.faults:
        return "it injects faults"
    if scenario.controller not in ("firmware", "reference"):
        return f"its controller is {scenario.controller}"
    if not scenario.sigma_rate_limit:
        return "it runs without the sigma rate limit"
    if scenario.mode == "realtime":
        return "it runs in real time"
    return None


def batch_of(plants: list) -> OdeBatch | LinearBatch | None:
    """The plants (reset) as one batch (built-in continuous models of one kind, or linear plants of one shape), or
    None when they are not one vectorised kind."""
    if batchable(plants):
        return OdeBatch(plants)
    if linear_batchable(plants):
        return LinearBatch(plants)
    return None


@dataclass
class _Steps:
    """What a block's lockstep recorded, row k = step k, column i = run i."""

    Y: np.ndarray
    U: np.ndarray
    sat: np.ndarray
    flags: np.ndarray
    sigma: np.ndarray
    X: np.ndarray | None  # the plants' states (the run's, when its twin is on)
    L: np.ndarray | None  # the laws' states (the twin's)
    steps: np.ndarray  # per run: steps taken (a plant that fails ends its run after that step)
    failed_at: np.ndarray  # per run: the step whose advance failed (-1: none)
    tick: np.ndarray  # (N,): when step k started, ns from the block's start
    lat: np.ndarray  # (N,): the law's call for the block, ns, shared by its runs


def _stack(runs: list[Run], name: str) -> np.ndarray:
    """The plans' ``name`` (N, width) of each run, stacked (N, B, width)."""
    return np.stack([getattr(r.plan, name) for r in runs], axis=1)


def _lockstep(runs: list[Run], batch: OdeBatch | LinearBatch, controller, *, Ts: float, steps: int,
              always_disturbed: bool, plant_state: bool, law_state: bool) -> _Steps:  # fmt: skip
    """Step ``controller`` (a block law) around ``batch`` for ``steps`` samples of each run's plan; a run whose
    plant fails stops there (its row steps on, unrecorded). ``always_disturbed``: the command plus the plan's
    disturbance goes to the plant even when it is zero (as the twin does; the run adds it only when the plan has
    one)."""
    B, noise, R, S, D = len(runs), _stack(runs, "noise"), _stack(runs, "R"), _stack(runs, "S"), _stack(runs, "D")
    disturbed = np.array([always_disturbed or bool(r.plan.D.any()) for r in runs])[:, None]
    m, p = D.shape[2], noise.shape[2]
    out = _Steps(Y=np.zeros((steps, B, p)), U=np.zeros((steps, B, m)), sat=np.zeros((steps, B), np.int64),
                 flags=np.zeros((steps, B), np.int64), sigma=np.full((steps, B), np.nan),
                 X=np.zeros((steps, *batch.X.shape)) if plant_state else None, L=None,
                 steps=np.full(B, steps), failed_at=np.full(B, -1), tick=np.zeros(steps),
                 lat=np.zeros(steps))  # fmt: skip
    alive = np.ones(B, dtype=bool)
    t_start = time.perf_counter_ns()
    for k in range(steps):
        Y = batch.outputs() + noise[k]
        out.Y[k] = Y
        if out.X is not None:
            out.X[k] = batch.X
        t0 = time.perf_counter_ns()
        st = controller.step(Y, R[k], S[k])
        out.lat[k], out.tick[k] = time.perf_counter_ns() - t0, t0 - t_start
        out.U[k], out.sat[k], out.flags[k], out.sigma[k] = st.u, st.sat, st.flags, st.sigma
        if law_state:
            L = controller.states()
            if out.L is None:
                out.L = np.zeros((steps, *L.shape))
            out.L[k] = L
        failed = batch.advance(np.where(disturbed, st.u + D[k], st.u), dt=Ts) & alive
        if failed.any():
            out.steps[failed], out.failed_at[failed] = k + 1, k
            alive &= ~failed
            if not alive.any():
                out.steps = np.minimum(out.steps, k + 1)
                break
    return out


def run_block(scenarios: list[Scenario], *, artifact: Artifact, library: Path | None = None) -> list[RunResult] | None:
    """Run ``scenarios`` (SIL runs of ``artifact`` that :func:`refusal` accepts, the same duration and controller)
    as one block; None when their plants cannot step as one batch (the caller runs them alone).

    Returns each run's :class:`~.bridge.RunResult`, in order, as :func:`~.bridge.run_scenario` returns it.
    """
    a, law, Ts = artifact, law_of(artifact), artifact.Ts
    plants = [build_plant(sc, artifact=a) for sc in scenarios]
    try:
        if not (batchable(plants) or linear_batchable(plants)):
            return None
        runs = [prepare_run(sc, law=law, artifact=a, plant=pl, source="(given as an object)")
                for sc, pl in zip(scenarios, plants)]  # fmt: skip
        if len({r.plan.N for r in runs}) != 1:
            return None
        batch = batch_of(plants)
        firmware = scenarios[0].controller == "firmware"
        block = len(runs)
        controller = law.native_block(a, block, library=library) if firmware else law.reference_block(a, block)
        t0 = time.perf_counter()
        rec = _lockstep(runs, batch, controller, Ts=Ts, steps=runs[0].plan.N,
                        always_disturbed=False, plant_state=any(sc.twin for sc in scenarios),
                        law_state=False)  # fmt: skip
        wall = time.perf_counter() - t0
    finally:
        for pl in plants:
            pl.close()
    t0 = time.perf_counter()
    twins = _twins(runs, law=law, artifact=a, steps=rec.steps)
    twins_s = (time.perf_counter() - t0) / len(runs)
    results = []
    for i, run in enumerate(runs):
        _record(
            run, rec, i, describe=dict(controller.describe) | {"block": len(runs)}, ran=law.label if firmware else None
        )
        reason = None if rec.failed_at[i] < 0 else f"plant failed at step {rec.failed_at[i]}: {non_finite(batch.name)}"
        outcome = Outcome(steps=int(rec.steps[i]), reason=reason, wall_s=wall / len(runs), overruns=0)
        results.append(run.result(outcome, twins=twins[i], twins_s=twins_s))
    return results


def _record(run: Run, rec: _Steps, i: int, *, describe: dict, ran: str | None) -> None:
    """Fill run ``i``'s recorder from the block's columns, as its own loop would have (``endpoint`` None: no link)."""
    r, steps = run.rec, int(rec.steps[i])
    r.Y[:steps], r.U[:steps], r.SATBITS[:steps] = rec.Y[:steps, i], rec.U[:steps, i], rec.sat[:steps, i]
    r.FLAGS[:steps], r.SIGMA[:steps], r.GOT[:steps] = rec.flags[:steps, i], rec.sigma[:steps, i], True
    r.LAT[:steps], r.TICK[:steps] = rec.lat[:steps], rec.tick[:steps]
    r.SENT[:steps], r.BACK[:steps] = rec.tick[:steps], rec.tick[:steps] + rec.lat[:steps]
    if rec.X is not None and run.scenario.twin:
        r.X[:steps] = rec.X[:steps, i]
    run.endpoint, run.ran = None, ran
    run.info = {"transport": dict(SIL), "controller": describe}


def _twins(runs: list[Run], *, law, artifact: Artifact, steps: np.ndarray) -> list:
    """Each run's twins: the closed-loop twins of the runs that ask for one stepped as a block (the float64
    reference of each around a second block of plants), the model twin by the function a run alone uses."""
    want = [i for i, r in enumerate(runs) if r.scenario.twin]
    traces: dict[int, object] = {}
    failed: dict[int, str] = {}
    if want:
        sub = [runs[i] for i in want]
        plants = [build_plant(r.scenario, artifact=artifact) for r in sub]
        try:
            for r, pl in zip(sub, plants):
                pl.reset(initial=r.scenario.initial_state)
            batch = batch_of(plants)
            longest = int(max(steps[want]))
            tw = _lockstep(sub, batch, law.reference_block(artifact, len(sub)), Ts=artifact.Ts,
                           steps=longest, always_disturbed=True, plant_state=False,
                           law_state=True)  # fmt: skip
        finally:
            for pl in plants:
                pl.close()
        traces, failed = _twin_traces(want, tw, steps=steps, name=batch.name)
    return [with_model_twin(law, artifact, scenario=r.scenario, plan=r.plan, start=r.start, steps=int(steps[i]),
                            twin=traces.get(i), twin_failed=failed.get(i))
            for i, r in enumerate(runs)]  # fmt: skip


def _twin_traces(want: list[int], tw: _Steps, *, steps: np.ndarray, name: str) -> tuple[dict, dict]:
    """Run i's :class:`~gainlink.proof.twin.TwinTrace` over its own steps, or why its twin's plant failed in them."""
    from gainlink.proof.twin import TwinTrace

    traces, failed = {}, {}
    for j, i in enumerate(want):
        n = int(steps[i])
        if 0 <= tw.failed_at[j] < n:
            failed[i] = non_finite(name)
            continue
        state = tw.L[:n, j] if (tw.L is not None and n) else np.zeros((0, 0))
        traces[i] = TwinTrace(
            y=tw.Y[:n, j].copy(), u=tw.U[:n, j].copy(), state=state.copy(), sigma=tw.sigma[:n, j].copy()
        )
    return traces, failed
