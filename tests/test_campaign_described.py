"""A block's task carries its runs described (each grid point's scenario once, each run's draw-table row and seed), and
the worker makes from that the runs the plan gives.

Oracles: the plan's own runs (``plan.runs[k]``, each made whole: its scenario built from the campaign's base with
every axis applied), compared as JSON text (key order and number types too: the text the record stores), and each
run's scenario parsed on its own (``worker._scenario``: the full parse) against the worker's.
"""

from __future__ import annotations

import copy
import json
import pickle
import shutil

import numpy as np
import pytest
from gainlink.fileio import read_toml
from gainlink.hil.campaign import parse_campaign, worker
from gainlink.hil.campaign.jsontext import object_texts
from gainlink.hil.campaign.plan import DescribedRuns, plan_campaign, task_uses
from support.paths import EXAMPLES

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")

PENDULUM = {"kind": "cart_pendulum", "outputs": ["x", "theta"], "step": 0.005,
            "parameters": {"M": 1.0, "m": 0.1, "l": 0.5, "g": 9.81}}  # fmt: skip
SCALE_M = {"name": "M", "target": "plant.parameters.M", "distribution": "uniform", "low": 0.8, "high": 1.2,
           "apply": "scale"}  # fmt: skip
ADD_M = {"name": "m", "target": "plant.parameters.m", "distribution": "normal", "mean": 0.0, "std": 0.005,
         "apply": "add"}  # fmt: skip
CHOOSE_L = {"name": "l", "target": "plant.parameters.l", "distribution": "choice", "values": [0.45, 0.5, 0.55]}
INITIAL = {"name": "th0", "target": "initial_state.theta", "distribution": "uniform", "low": -0.05, "high": 0.05}
NOISE = {"name": "nz", "target": "noise.theta", "distribution": "loguniform", "low": 1e-4, "high": 1e-3}
FAULT = {"name": "fault", "target": "faults[0].start", "distribution": "uniform", "low": 0.1, "high": 0.3}
NOISES = {"name": "nzs", "target": "noise", "distribution": "choice",
          "values": [{"x": 5e-4, "theta": 5e-4}, {"x": 1e-3}]}  # fmt: skip
GRID = [{"name": "aw", "target": "spec.limits.anti_windup", "values": ["clamp", "backcalc"]},
        {"name": "x0", "target": "initial_state.x", "values": [0.2, 0.6]}]  # fmt: skip


def _campaign(draws: list, *, runs: int = 12, grid: list = GRID, plant: dict = PENDULUM, faults: bool = False):
    scenario = {"duration": 0.4, "initial_state": {"x": 0.3}, "model_twin": False,
                "noise": {"x": 0.0005, "theta": 0.0005}, "plant": copy.deepcopy(plant)}  # fmt: skip
    if faults:
        scenario["faults"] = [{"kind": "nan", "start": 0.2, "stop": 0.22}]
    return parse_campaign({"name": "described", "kind": "sil", "seed": 11, "runs": runs,
                           "spec": str(EXAMPLES / "pendulum.toml"), "scenario": scenario, "grid": grid,
                           "draw": draws, "criteria": {"stable": True}})  # fmt: skip


def _shipped(name: str, runs: int | None = None):
    path = EXAMPLES / "campaigns" / f"{name}.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    if runs is not None:
        data["runs"] = runs
    return parse_campaign(data, path=path)


def _blocks_of(n: int) -> list[np.ndarray]:
    """Plan indices as the runner cuts them (in plan order) and as a resumed campaign leaves them (gaps): the whole
    plan, a block across grid points with gaps, a single run (a failed block's retry)."""
    rng = np.random.default_rng(3)
    gaps = np.sort(rng.choice(n, size=max(1, n * 2 // 3), replace=False))
    return [np.arange(n), gaps, np.array([n - 1])]


def _as_text(run) -> str:
    return json.dumps(run)


def _check_same_runs(plan, described: bool) -> None:
    """Each block's task gives, run for run, the plan's own run (``plan.runs[k]``), as text, by iteration and by
    index, and again after the pickle round trip the task travels in; and where it gives its scenarios as column
    trees (what a block file's records are written from), their JSON texts are the plan's runs' scenarios'."""
    for block in _blocks_of(len(plan.runs)):
        task = plan.runs.task(block)
        assert isinstance(task, DescribedRuns) is described
        want = [_as_text((p.artifact_sha256, p.scenario, p.seed)) for p in (plan.runs[k] for k in block.tolist())]
        travelled = pickle.loads(pickle.dumps(task, protocol=pickle.HIGHEST_PROTOCOL))
        assert [_as_text(r) for r in task] == want
        assert [_as_text(travelled[i]) for i in range(len(block))] == want
        scenarios = [json.dumps({"s": plan.runs[k].scenario}, sort_keys=True, separators=(",", ":"))
                     for k in block.tolist()]  # fmt: skip
        if described:  # the runs a worker makes: by index (a part at a time), alone, and their artifacts and seeds
            assert [_as_text(r) for r in travelled.made_runs()] == want
            alone = travelled.made_runs()
            assert [_as_text(alone.one(i)) for i in reversed(range(len(block)))] == want[::-1]
            assert alone.columns() == ([p.artifact_sha256 for p in (plan.runs[k] for k in block.tolist())],
                                       [plan.runs[k].seed for k in block.tolist()])  # fmt: skip
        for made in (task, travelled) if described else ():  # task: its parts' slots made by iterating it
            trees = made.scenario_trees()
            if trees is not None:
                assert [(a, b) for a, b, _ in trees] == [(p.start, p.stop) for p in made.parts]
                assert [t for a, b, tree in trees for t in object_texts({"s": tree}, b - a)] == scenarios
        shas, fmus = task_uses(travelled)
        assert shas == {plan.runs[k].artifact_sha256 for k in block.tolist()}
        assert fmus == {
            str(p.scenario["plant"].get("path", "")).removeprefix("sha256:")
            for p in (plan.runs[k] for k in block.tolist())
            if p.scenario["plant"].get("kind") == "fmu"
        }


@pytest.mark.parametrize(
    "name",
    [
        "pendulum_mass_uncertainty",
        "pendulum_mpc_mass_uncertainty",
        pytest.param("tank_sigma_rate", marks=pytest.mark.matrix),  # its scheduled design: ~28 s
        "wood_berry_gain_deadtime",
    ],
)
def test_a_shipped_campaigns_tasks_describe_the_plans_own_runs(name):
    """The shipped campaigns (draws of plant parameters over a spec grid; a scenario grid; an FMU plant over a grid of
    its parameters): every task is described and gives the plan's runs, text for text."""
    runs = 9 if name.startswith("pendulum") else None
    plan = plan_campaign(_shipped(name, runs))
    assert plan.runs.describable
    # the pendulums' scenarios as column trees (an FMU's is named after its draws: each run made)
    assert (plan.runs.task(np.arange(len(plan.runs))).scenario_trees() is not None) is name.startswith("pendulum")
    _check_same_runs(plan, described=True)


GRID_M = [{"name": "M0", "target": "plant.parameters.M", "values": [0.9, 1.1]}]  # a draw scales it too


@pytest.mark.parametrize(
    ("draws", "faults", "grid", "leaves"),
    [
        ([SCALE_M, ADD_M, CHOOSE_L], False, GRID, True),  # the plant's drawn tables: set, scaled, shifted, chosen
        ([SCALE_M, INITIAL, NOISE], False, GRID, True),  # an initial state and a noise level drawn (a new table key)
        ([CHOOSE_L, FAULT, NOISES], True, GRID, True),  # a fault's start drawn, a table chosen
        ([SCALE_M, NOISE], False, GRID_M, False),  # a grid axis and a draw axis on one path: each run made whole
    ],
)
def test_a_campaigns_tasks_over_grid_axes_and_draws_describe_the_plans_own_runs(draws, faults, grid, leaves):
    """Grid axes on the spec and on the scenario, choice draws, initial-state, noise and fault draws: each task is
    described and gives the plan's runs, text for text (its values put at the draws' paths, or, where two axes share a
    path, each run made from its grid point's scenario by the plan's own setter); a task's bytes are its grid points'
    scenarios and a few bytes a run (1,000 runs: under 48 bytes a run, the seed and the numbers 8 bytes each)."""
    plan = plan_campaign(_campaign(draws, faults=faults, grid=grid))
    assert plan.runs.task(np.arange(2)).leaves is leaves
    # as column trees but where a draw's path runs through a list (the faults) or its runs are each made whole
    assert (plan.runs.task(np.arange(len(plan.runs))).scenario_trees() is not None) is (leaves and not faults)
    assert list(plan.runs.task(np.arange(0))) == []
    _check_same_runs(plan, described=True)
    big = plan_campaign(_campaign(draws, faults=faults, runs=1000, grid=grid[:1]))
    task = big.runs.task(np.arange(1000))
    size = len(pickle.dumps(task, protocol=pickle.HIGHEST_PROTOCOL))
    assert size / 1000 < 48
    list(task), task.scenario_trees()  # the slots made from it (kept for its trees) do not travel with it
    assert len(pickle.dumps(task, protocol=pickle.HIGHEST_PROTOCOL)) == size


@pytest.mark.parametrize("drawn", ["parameter", "initial state"])
def test_an_fmu_plants_runs_are_described_and_its_file_travels_once(cart_fmu, drawn):
    """An FMU plant given by its file (no parameters table: a draw makes it) whose parameter is drawn, or whose
    initial state is: described (its grid point's FMU named by sha256 after the draws, as the plan names it), the
    plan's runs text for text, the FMU among the task's uses."""
    plant = {"kind": "fmu", "path": str(cart_fmu), "interface": "cs"}
    draw = {"name": "m", "target": "plant.parameters.m", "distribution": "uniform", "low": 0.08, "high": 0.12}
    plan = plan_campaign(_campaign([draw if drawn == "parameter" else INITIAL], plant=plant, grid=GRID[1:]))
    assert len(plan.blobs) == 1
    _check_same_runs(plan, described=True)


def test_runs_the_plan_cannot_describe_are_enumerated_as_the_plan_makes_them(cart_fmu, tmp_path):
    """A spec.* draw axis (each run its own design) and a draw of the FMU file (each run its own FMU): the tasks carry
    each run's inputs, the plan's runs text for text."""
    spec_draw = {"name": "q", "target": "spec.limits.u_max[0]", "distribution": "uniform", "low": 18.0, "high": 22.0}
    plan = plan_campaign(_campaign([SCALE_M, spec_draw], runs=4, grid=GRID[1:]))
    assert not plan.runs.describable
    _check_same_runs(plan, described=False)
    other = tmp_path / "other.fmu"
    shutil.copy(cart_fmu, other)
    plant = {"kind": "fmu", "path": str(cart_fmu), "interface": "cs", "parameters": {"m": 0.1}}
    file_draw = {
        "name": "file",
        "target": "plant.path",
        "distribution": "choice",
        "values": [str(cart_fmu), str(other)],
    }
    plan = plan_campaign(_campaign([file_draw], runs=4, plant=plant, grid=GRID[1:]))
    assert not plan.runs.describable
    _check_same_runs(plan, described=False)


@pytest.mark.parametrize("draws", [[SCALE_M, ADD_M, CHOOSE_L], [SCALE_M, INITIAL, NOISE]])
def test_a_described_tasks_runs_parse_as_each_run_alone_and_group_as_enumerated(draws):
    """The worker's runs of a described task: each run's scenario equals its plan run's full parse (the plant's
    drawn tables given to the grid point's first parse, or each run parsed when a draw lies elsewhere), and the
    runs step in the same blocks as the same runs enumerated."""
    plan = plan_campaign(_campaign(draws, runs=6))
    block = np.arange(len(plan.runs))[1::2]  # across the grid points, with gaps
    described, enumerated = plan.runs.task(block), plan.runs.inputs(block)
    assert isinstance(described, DescribedRuns)
    groups = worker._blocks(plan.artifacts, described.made_runs(), {})
    assert {key: [i for i, _, _ in m] for key, m in groups.items()} == {
        key: [i for i, _, _ in m] for key, m in worker._blocks(plan.artifacts, enumerated, {}).items()
    }
    assert sorted(i for m in groups.values() for i, _, _ in m) == list(range(len(block)))
    for members in groups.values():
        for i, art, got in members:
            p = plan.runs[int(block[i])]
            path = worker._ARTIFACTS[art.sha256][1]
            assert got == worker._scenario(p.scenario, artifact_path=path, seed=p.seed, blobs={}, kind="sil")


def test_a_described_tasks_records_are_the_enumerated_tasks_run_for_run():
    """``batch_records`` of a described task (blocks across grid points, a run alone with a fault) and of the same runs
    enumerated: the same statuses, measures and downsampled traces bit for bit, and each record's inputs are the
    plan's run."""
    from gainlink.hil.campaign.block_file import with_inputs

    plan = plan_campaign(_campaign([SCALE_M, INITIAL], runs=4))
    block = np.arange(len(plan.runs))[::3]
    described = plan.runs.task(block)
    got = worker.batch_records("sil", plan.artifacts, described)
    want = worker.batch_records("sil", plan.artifacts, plan.runs.inputs(block))
    for i, (a, b) in enumerate(zip(got, want)):
        assert a["status"] == b["status"] == "done" and a["measures"] == b["measures"], i
        assert all(np.array_equal(a["trace"][k], b["trace"][k]) for k in "tyur"), i
        p = plan.runs[int(block[i])]
        inputs = with_inputs(a, described[i], kind="sil")["inputs"]
        assert json.dumps(inputs["scenario"]) == json.dumps(p.scenario) and inputs["seed"] == p.seed


def test_a_described_tasks_block_file_holds_the_enumerated_tasks_records_without_making_each_runs_scenario(
    monkeypatch,
):
    """The block file a worker makes of a described task whose draws all set the plant's drawn numbers: its records
    (each run's id, inputs, link, status) are the same runs enumerated's, text for text;
    the worker made no run's scenario but each grid point's first (``part_runs`` refused: the drawn tables come from
    the task's columns, the record texts from its column trees and its artifacts and seeds)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from gainlink.hil.campaign.block_texts import record_texts

    plan = plan_campaign(_campaign([SCALE_M, ADD_M, CHOOSE_L], runs=5))
    block = np.arange(len(plan.runs))[1::2]
    ids = [plan.runs[k].id for k in block.tolist()]

    def stored(runs) -> pa.Table:
        packed = pickle.dumps((ids, runs, None))
        return pq.read_table(pa.BufferReader(worker.execute_packed("sil", plan.artifacts, packed, campaign="c")))

    want = stored(plan.runs.inputs(block))

    def refused(self, part):
        raise AssertionError("a run's scenario made")

    monkeypatch.setattr(DescribedRuns, "part_runs", refused)
    got = stored(plan.runs.task(block))
    for column in ("id", "status"):  # the metrics hold timings (latency, steps a second): run's own
        assert got.column(column).to_pylist() == want.column(column).to_pylist(), column
    assert record_texts(got) == record_texts(want)
    assert [json.loads(r)["inputs"]["seed"] for r in record_texts(got)] == [plan.runs[k].seed for k in block.tolist()]
