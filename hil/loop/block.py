"""A campaign block: SIL runs of one artifact stepped together, in lockstep, each answering what it answers alone.

The block's loop over all its steps is one C call where the C covers its plants and law (:mod:`.lockstep`: the
built-in models' compiled RK4, a law's host library or the lq law's compiled float64 reference), the numpy loop
below (:func:`_python_lockstep`, its oracle, bit for bit) elsewhere; the run's controller description says which ran.
Per step ``k`` every run of the block is sampled (its plant's outputs plus its own noise, one stacked array), the law
answers the whole block in one call (:meth:`gainlink.laws.Law.native_block`: one C call for the host C;
:meth:`gainlink.laws.Law.reference_block`: the float64 law, as columns for the lq law) and the plants advance together
(:class:`~..plants.models.OdeBatch`, the RK4 kernel a plant alone steps with a batch of one;
:class:`~..plants.linear.LinearBatch`, each run's own matrices). The closed-loop twin is stepped the same way afterwards
(the float64 reference of each run around a second batch of the runs' plants). Each run is prepared (plan, noise,
references) and reported (the law's report) by the functions a run alone uses (:mod:`.bridge`), what the runs share
planned once (:func:`prepare_block`: the first run's plan, each run's own noise) and their metrics computed as columns
(:func:`~.block_metrics.block_metrics`, each run's what :func:`~.metrics.compute_metrics` gives it), so a run's trace
and verdict are the same bit for bit whichever path ran it (timing columns aside: a block times its calls, not a run).

What cannot step so (:func:`refusal`: a link, faults, a plant that is not vectorised, a plant that follows external
signals) is left to the caller, which runs it alone; so is a run whose plant cannot be built (:func:`run_block`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from gainlink.errors import GainlinkError
from gainlink.laws import law_of
from gainlink.shipping.artifact import Artifact

from ..plants.linear import LinearBatch, linear_batchable
from ..plants.models import OdeBatch, batchable, non_finite
from . import lockstep
from .block_metrics import BlockMetrics, metric_trees
from .bridge import Run, RunResult, build_plant, in_process, prepare_run
from .closed_loop import Outcome
from .lockstep import Steps
from .metrics import timing
from .plan import describe_artifact, describe_plant, plans_alike, saturated
from .scenario import Scenario
from .twins import with_model_twin

SIL = {"kind": "sil (in-process, no link)"}  # the run's transport block, as a run alone reports it
SHARED = ("GOT", "LAT", "TICK", "SENT", "BACK", "DUE", "NAN", "X")  # a run's record arrays its block's runs share
SOURCE = "(given as an object)"  # where the artifact came from, as a run alone given the object reports it


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


def _stack(runs: list[Run], name: str) -> np.ndarray:
    """The plans' ``name`` (N, width) of each run, stacked (N, B, width): a read-only view of one array when the
    runs share it (:func:`~.plan.plan_like`)."""
    first = getattr(runs[0].plan, name)
    if all(getattr(r.plan, name) is first for r in runs):
        return np.broadcast_to(first[:, None, :], (first.shape[0], len(runs), first.shape[1]))
    return np.stack([getattr(r.plan, name) for r in runs], axis=1)


def _disturbed(runs: list[Run], always: bool) -> np.ndarray | bool:
    """Per run (B, 1): whether its command goes to the plant with its plan's disturbance added (``always``, or the
    plan has one; asked once per array: a block's runs share one); True or False when it is the same for every run."""
    answers: dict[int, bool] = {}
    for r in runs:
        if id(r.plan.D) not in answers:
            answers[id(r.plan.D)] = always or bool(r.plan.D.any())
    if len(set(answers.values())) == 1:
        return next(iter(answers.values()))
    return np.array([answers[id(r.plan.D)] for r in runs])[:, None]


def _command(u: np.ndarray, d: np.ndarray, disturbed: np.ndarray | bool) -> np.ndarray:
    """What the plants are given: each run's command, plus its disturbance where ``disturbed`` (:func:`_disturbed`)."""
    if disturbed is True:
        return u + d
    if disturbed is False:
        return u
    return np.where(disturbed, u + d, u)


CHUNK = 64  # steps a record gathers before they move run-major (1,000 runs of a 4-wide state: 2 MB, in cache)


class _RunMajor:
    """One quantity of every run at every step, written a step at a time as (step, run) rows, moved run-major
    (``out[i]``: run i's rows, contiguous) every :data:`CHUNK` steps while those rows are in cache: one transpose of
    the whole record at the end cost twice as much. The move copies each (step, run) record as one item of its
    bytes (:func:`_items`): numpy's transposing copy of a (64, 1000, 2) float array loops over the 2 numbers of each
    record, 4-5x slower."""

    def __init__(self, steps: int, runs: int, width: tuple = (), dtype: type = float) -> None:
        self.rows = np.empty((min(CHUNK, steps), runs, *width), dtype)
        self.out = np.empty((runs, steps, *width), dtype)
        self._rows, self._out = _items(self.rows), _items(self.out)
        self.k0 = 0

    def at(self, k: int) -> np.ndarray:
        """The row of step ``k`` to write (called for each step in turn)."""
        if k - self.k0 == len(self.rows):
            self._move(k)
        return self.rows[k - self.k0]

    def _move(self, end: int) -> None:
        self._out[:, self.k0 : end] = self._rows[: end - self.k0].T
        self.k0 = end

    def taken(self, steps: int) -> np.ndarray:
        """Every run's first ``steps`` rows (run, step, ...), once the last is written."""
        self._move(steps)
        return self.out[:, :steps]


def _items(a: np.ndarray) -> np.ndarray:
    """``a`` (d0, d1, ...) as (d0, d1) items of raw bytes, one per record (the same memory)."""
    width = int(np.prod(a.shape[2:], dtype=int))
    if width == 0:
        return np.empty(a.shape[:2], dtype=np.int8)  # nothing to move
    return a.reshape(*a.shape[:2], width).view(np.dtype((np.void, a.dtype.itemsize * width))).reshape(a.shape[:2])


def _lockstep(runs: list[Run], batch: OdeBatch | LinearBatch, controller, *, Ts: float, steps: int,
              always_disturbed: bool, plant_state: bool, law_state: slice | None) -> Steps:  # fmt: skip
    """Step ``controller`` (a block law) around ``batch`` for ``steps`` samples of each run's plan; a run whose
    plant fails stops there (its row steps on, unrecorded). ``always_disturbed``: the command plus the plan's
    disturbance goes to the plant even when it is zero (as the twin does; the run adds it only when the plan has
    one). ``plant_state``: the plants' states recorded; ``law_state``: these columns of the laws' states recorded
    (the twin's lockstep, its integrators: its commands' saturation and flags are not recorded, its trace has
    none); None: no law state.

    In one C call for all the steps where the C covers the plants and the law (:mod:`.lockstep`: the built-in
    models' compiled RK4 with a law's host library or the lq law's compiled float64 reference); elsewhere (linear
    plants, a user's vectorised model, a law's float64 reference without a C step, no C compiler) the numpy loop
    (:func:`_python_lockstep`), whose records the C's equal bit for bit. :attr:`Steps.loop` says which ran."""
    disturbed = _disturbed(runs, always_disturbed)
    why = lockstep.why_not(batch, controller)
    if why is None:
        return lockstep.run(runs, batch, controller, Ts=Ts, steps=steps, disturbed=disturbed,
                            plant_state=plant_state, law_state=law_state)  # fmt: skip
    return _python_lockstep(runs, batch, controller, Ts=Ts, steps=steps, disturbed=disturbed,
                            plant_state=plant_state, law_state=law_state, loop=why)  # fmt: skip


def _python_lockstep(runs: list[Run], batch: OdeBatch | LinearBatch, controller, *, Ts: float, steps: int,
                     disturbed: np.ndarray | bool, plant_state: bool, law_state: slice | None,
                     loop: str) -> Steps:  # fmt: skip
    """:func:`_lockstep` in numpy (``disturbed``: :func:`_disturbed`; ``loop``: why it runs here, recorded). A
    step is array operations over the block and one call of the law: the samples, references and noise of every
    step are stacked before the first (each run's noise drawn by its own plan, as alone) and what a step gives is
    written into the rows of :class:`_RunMajor` records."""
    B, noise, R, S, D = len(runs), _stack(runs, "noise"), _stack(runs, "R"), _stack(runs, "S"), _stack(runs, "D")
    Y, U = _RunMajor(steps, B, (noise.shape[2],)), _RunMajor(steps, B, (D.shape[2],))
    sigma: _RunMajor | None = None  # made at the first step when the law has a sigma
    twin = law_state is not None
    sat, flags = (None, None) if twin else (_RunMajor(steps, B, (), np.int64), _RunMajor(steps, B, (), np.int64))
    X = _RunMajor(steps, B, batch.X.shape[1:]) if plant_state else None
    L = _RunMajor(steps, B, controller.states()[:, law_state].shape[1:]) if law_state is not None else None
    done, failed_at, tick, lat = np.full(B, steps), np.full(B, -1), np.zeros(steps), np.zeros(steps)
    alive = np.ones(B, dtype=bool)
    t_start = time.perf_counter_ns()
    for k in range(steps):
        y = np.add(batch.outputs(), noise[k], out=Y.at(k))
        if X is not None:
            X.at(k)[:] = batch.X
        t0 = time.perf_counter_ns()
        st = controller.step(y, R[k], S[k])
        lat[k], tick[k] = time.perf_counter_ns() - t0, t0 - t_start
        U.at(k)[:] = st.u
        if st.sigma is not None:
            if sigma is None:
                sigma = _RunMajor(steps, B)
            sigma.at(k)[:] = st.sigma
        if sat is not None and flags is not None:
            sat.at(k)[:], flags.at(k)[:] = st.sat, st.flags
        if L is not None:
            L.at(k)[:] = controller.states()[:, law_state]
        failed = batch.advance(_command(st.u, D[k], disturbed), dt=Ts) & alive
        if failed.any():
            done[failed], failed_at[failed] = k + 1, k
            alive &= ~failed
            if not alive.any():
                done = np.minimum(done, k + 1)
                break
    taken = int(done.max()) if B else 0  # rows past every run's end were never written

    def out(record: _RunMajor | None) -> np.ndarray | None:
        return None if record is None else record.taken(taken)

    return Steps(Y=out(Y), U=out(U), sat=out(sat), flags=out(flags), sigma=out(sigma), X=out(X), L=out(L),
                  steps=done, failed_at=failed_at, tick=tick, lat=lat, loop=loop)  # fmt: skip


def run_block(scenarios: list[Scenario], *, artifact: Artifact, library: Path | None = None) -> BlockResults | None:
    """Run ``scenarios`` (SIL runs of ``artifact`` that :func:`refusal` accepts, the same duration and controller)
    as one block; None when their plants cannot step as one batch (the caller runs them alone).

    Returns each run's :class:`~.bridge.RunResult`, in order, as :func:`~.bridge.run_scenario` returns it; None in
    the place of a run whose plant cannot be built (its drawn numbers are wrong: the caller runs it alone, and it
    records its own error): a :class:`BlockResults`, which also holds the runs' metrics as columns.
    """
    a, law, Ts = artifact, law_of(artifact), artifact.Ts
    plants = _plants(scenarios, artifact=a)
    kept = [i for i, pl in enumerate(plants) if pl is not None]
    try:
        live = [plants[i] for i in kept]
        if not live or not (batchable(live) or linear_batchable(live)):
            return None
        runs = prepare_block([scenarios[i] for i in kept], law=law, artifact=a, plants=live)
        batch = batch_of(live)
        firmware = scenarios[0].controller == "firmware"
        controller = law.native_block(a, len(runs), library=library) if firmware else law.reference_block(a, len(runs))
        t0 = time.perf_counter()
        rec = _lockstep(runs, batch, controller, Ts=Ts, steps=runs[0].plan.N,
                        always_disturbed=False, plant_state=any(r.scenario.twin for r in runs),
                        law_state=None)  # fmt: skip
        wall = time.perf_counter() - t0
        t0 = time.perf_counter()
        twins = _twins(runs, law=law, artifact=a, steps=rec.steps)
        twins_s = (time.perf_counter() - t0) / len(runs)
    finally:
        for pl in plants:
            if pl is not None:
                pl.close()
    described = dict(controller.describe) | {"block": len(runs), "loop": rec.loop}
    results, trees = _results(
        runs,
        rec,
        twins,
        describe=described,
        ran=law.label if firmware else None,
        wall_s=wall / len(runs),
        twins_s=twins_s,
        failure=non_finite(batch.name),
    )
    out: list[RunResult | None] = [None] * len(scenarios)
    for i, result in zip(kept, results):
        out[i] = result
    return BlockResults(out, trees.at(kept, len(scenarios)))


@dataclasses.dataclass(frozen=True)
class BlockResults(Sequence):
    """:func:`run_block`'s answer: each scenario's :class:`~.bridge.RunResult` in order (None for a run whose plant
    could not be built), and the block's metrics as column trees (:class:`~.block_metrics.BlockMetrics`, by the
    scenarios' positions), which a campaign's block file is made from without a run's dict."""

    results: list
    metrics: BlockMetrics

    def __getitem__(self, i):  # type: ignore[override]
        return self.results[i]

    def __len__(self) -> int:
        return len(self.results)


def _plants(scenarios: list[Scenario], *, artifact: Artifact) -> list:
    """Each run's plant, or None for a run whose plant cannot be built (a drawn number its plant refuses)."""
    plants = []
    for sc in scenarios:
        try:
            plants.append(build_plant(sc, artifact=artifact))
        except GainlinkError:
            plants.append(None)
    return plants


def prepare_block(scenarios: list[Scenario], *, law, artifact: Artifact, plants: list) -> list[Run]:
    """Each run prepared as :func:`~.bridge.prepare_run` prepares it alone (its recorder made without arrays: they
    are the block's), planned once for the block: a run planned as the first but for its seed (its scenario differs
    only in its seed and its plant's drawn numbers, the same signals) takes the first's plan with its own noise
    (:func:`~.plan.plan_like`)."""
    first = prepare_run(scenarios[0], law=law, artifact=artifact, plant=plants[0], source=SOURCE, record=False)
    runs, p0 = [first], plants[0]
    for sc, pl in zip(scenarios[1:], plants[1:]):
        alike = plans_alike(sc, first.scenario) and (pl.input_names, pl.output_names) == (
            p0.input_names,
            p0.output_names,
        )
        runs.append(prepare_run(sc, law=law, artifact=artifact, plant=pl, source=SOURCE, record=False,
                                like=first if alike else None))  # fmt: skip
    return runs


def _results(runs: list[Run], rec: Steps, twins: list, *, describe: dict, ran: str | None, wall_s: float,
             twins_s: float, failure: str) -> tuple[list[RunResult], BlockMetrics]:  # fmt: skip
    """Each run's result from the block's record, and the runs' metrics as column trees (completed with what each
    result adds). What the runs share is computed once: the artifact's description and the timing of the block's
    calls (per number of steps taken: a run whose plant failed has fewer); the metrics as columns over the block's
    traces (:func:`~.block_metrics.metric_trees`)."""
    artifact_info = describe_artifact(runs[0].law, runs[0].a, SOURCE)
    timed: dict[int, dict] = {}
    N, states = rec.lat.size, len(runs[0].plant.state_names)
    shared = {"GOT": np.ones(N, dtype=bool), "LAT": rec.lat, "TICK": rec.tick, "SENT": rec.tick,
              "BACK": rec.tick + rec.lat, "DUE": np.full(N, np.nan), "NAN": np.zeros(N, dtype=bool),
              "X": np.full((N, states), np.nan), "NAN_SIGMA": np.full(N, np.nan),
              "SAT": saturated(rec.sat, rec.U.shape[2])}  # fmt: skip
    traces = []
    for i, run in enumerate(runs):
        steps = int(rec.steps[i])
        if steps not in timed:
            timed[steps] = timing(rec.lat[:steps], rec.tick[:steps], np.full(steps, np.nan), mode="sil")
        _record(run, rec, i, shared=shared, describe=describe, ran=ran)
        traces.append(run.trace(steps, twins=twins[i]))
    trees = metric_trees(traces, artifact=runs[0].a, mode="sil", late=0,
                         period_s=[r.plan.period_s for r in runs], model_start=[t.model_note for t in twins],
                         timed=[timed[int(n)] for n in rec.steps])  # fmt: skip
    metrics = trees.rows()
    results, plant_info = [], _plant_infos()
    for i, run in enumerate(runs):
        reason = None if rec.failed_at[i] < 0 else f"plant failed at step {rec.failed_at[i]}: {failure}"
        outcome = Outcome(steps=int(rec.steps[i]), reason=reason, wall_s=wall_s, overruns=0)
        results.append(run.result(outcome, twins=twins[i], twins_s=twins_s, artifact_info=artifact_info,
                                  plant_info=plant_info(run.plant), trace=traces[i], metrics=metrics[i]))  # fmt: skip
    return results, trees.completed([r.metrics for r in results])


def _plant_infos():
    """:func:`~.plan.describe_plant` of a block's plants, made once per kind and signals (the runs of one kind
    share it: the block's plants are built-in models or linear plants, without an FMU's interface)."""
    made: dict[tuple, dict] = {}

    def info(plant) -> dict:
        key = (type(plant), plant.name, *map(tuple, (plant.input_names, plant.output_names, plant.state_names)))
        if key not in made:
            made[key] = describe_plant(plant)
        return made[key]

    return info


def _record(run: Run, rec: Steps, i: int, *, shared: dict, describe: dict, ran: str | None) -> None:
    """Point run ``i``'s recorder (made without arrays) at its rows of the block's record (views, not copies: its
    trace reads the steps it took, as its own loop would have recorded them) and at what the runs share (the plant's
    states NaN without a twin, as a run alone records them); ``endpoint`` None: no link."""
    r = run.rec
    r.Y, r.U, r.SATBITS, r.FLAGS, r.SAT = rec.Y[i], rec.U[i], rec.sat[i], rec.flags[i], shared["SAT"][i]
    r.SIGMA = shared["NAN_SIGMA"] if rec.sigma is None else rec.sigma[i]
    for name in SHARED:
        setattr(r, name, shared[name])
    if rec.X is not None and run.scenario.twin:
        r.X = rec.X[i]
    run.endpoint, run.ran = None, ran
    run.info = {"transport": dict(SIL), "controller": describe}


def _twins(runs: list[Run], *, law, artifact: Artifact, steps: np.ndarray) -> list:
    """Each run's twins: the closed-loop twins of the runs that ask for one stepped as a block (the float64
    reference of each around a second batch of the runs' plants, reset; of the laws' states only the integrators
    recorded, all a run's trace reads of them), the model twin by the function a run alone uses."""
    want = [i for i, r in enumerate(runs) if r.scenario.twin]
    traces: dict[int, object] = {}
    failed: dict[int, str] = {}
    if want:
        sub = [runs[i] for i in want]
        for r in sub:  # the run's own plant, reset again: its batch stepped copies of its state, not the plant
            r.plant.reset(initial=r.scenario.initial_state)
        batch = batch_of([r.plant for r in sub])
        longest, columns = int(max(steps[want])), law.integrator_columns(artifact)
        tw = _lockstep(sub, batch, law.reference_block(artifact, len(sub)), Ts=artifact.Ts,
                       steps=longest, always_disturbed=True, plant_state=False,
                       law_state=slice(0, 0) if columns is None else columns)  # fmt: skip
        traces, failed = _twin_traces(want, tw, steps=steps, name=batch.name, integrators=columns is not None)
    return [with_model_twin(law, artifact, scenario=r.scenario, plan=r.plan, start=r.start, steps=int(steps[i]),
                            twin=traces.get(i), twin_failed=failed.get(i))
            for i, r in enumerate(runs)]  # fmt: skip


def _twin_traces(want: list[int], tw: Steps, *, steps: np.ndarray, name: str,
                 integrators: bool) -> tuple[dict, dict]:  # fmt: skip
    """Run i's :class:`~gainlink.proof.twin.TwinTrace` over its own steps, or why its twin's plant failed in them
    (``integrators``: the law keeps some, ``tw.L`` holds them; a run of no steps keeps the empty state a run alone
    records)."""
    from gainlink.proof.twin import TwinTrace

    traces, failed, nan = {}, {}, {}  # nan: the sigma of the twins of n steps of a law without one, shared
    for j, i in enumerate(want):
        n = int(steps[i])
        if 0 <= tw.failed_at[j] < n:
            failed[i] = non_finite(name)
            continue
        if tw.sigma is None:
            sigma = nan[n] if n in nan else nan.setdefault(n, np.full(n, np.nan))
        else:
            sigma = tw.sigma[j, :n]
        if not n:
            traces[i] = TwinTrace(y=tw.Y[j, :n], u=tw.U[j, :n], state=np.zeros((0, 0)), sigma=sigma)
            continue
        z = tw.L[j, :n] if (integrators and tw.L is not None) else None
        traces[i] = TwinTrace(y=tw.Y[j, :n], u=tw.U[j, :n], state=None, sigma=sigma, z=z)
    return traces, failed
