"""The campaign client's share of a campaign: planning checks the extremes of the draws instead of parsing every
run's scenario, and a report names each run without making its scenario again.

Oracles: each draw made by hand from its definition (``default_rng([seed, chunk])`` a chunk of 1,024 draws, the run
seeds first, as the plan's docstring says), the scenario parser on the run made alone, and the runs the generated
plan makes one at a time.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.hil.campaign import CampaignError, parse_campaign
from gainlink.hil.campaign import plan as plan_module
from gainlink.hil.campaign.plan import plan_campaign
from gainlink.hil.loop.scenario import parse_scenario
from support.campaign_plants import fmu_run
from support.paths import EXAMPLES

RUNS = 400


def _campaign(draws: list[dict], *, runs: int = RUNS, seed: int = 5) -> dict:
    return {
        "name": "client",
        "kind": "sil",
        "seed": seed,
        "runs": runs,
        "spec": str(EXAMPLES / "pendulum.toml"),
        "scenario": {"duration": 0.5, "noise": {"theta": 1e-3}, "plant": {"kind": "cart_pendulum"}},
        "grid": [{"target": "spec.limits.anti_windup", "values": ["clamp", "backcalc"]}],
        "draw": draws,
        "criteria": {"stable": True},
    }


UNIFORM_M = {"target": "plant.parameters.M", "distribution": "uniform", "low": 0.7, "high": 1.3}
CHOICE_X = {"target": "initial_state.x", "distribution": "choice", "values": [0.0, 0.5, 1.0]}


def _noise_draws(seed: int, runs: int, mean: float, std: float) -> np.ndarray:
    """Draw ``j``'s noise value by hand (``runs`` <= 1,024: every draw in chunk 0): ``default_rng([seed, 0])`` draws
    the chunk's 1,024 run seeds first, then each axis's 1,024 values in order (M, then noise)."""
    rng = np.random.default_rng([seed, 0])
    rng.integers(2**31 - 1, size=1024)
    rng.uniform(0.7, 1.3, size=1024)
    return rng.normal(mean, std, size=1024)[:runs]


def test_planning_parses_each_grid_points_extreme_draws_not_every_run(monkeypatch):
    """800 runs (2 grid points x 400 draws of a uniform and a choice axis): the parser sees, per grid point, draw 0,
    the smallest and the largest M and the first draw of each choice value (at most 6), not 400."""
    parsed = []

    def counting(data, **kw):
        parsed.append(data["plant"].get("parameters", {}).get("M"))
        return parse_scenario(data, **kw)

    monkeypatch.setattr(plan_module, "parse_scenario", counting)
    plan = plan_campaign(parse_campaign(_campaign([UNIFORM_M, CHOICE_X])))
    assert len(plan.runs) == 2 * RUNS
    assert 2 * 3 <= len(parsed) <= 2 * 6, len(parsed)
    drawn = [p.values["plant.parameters.M"] for p in plan.runs[:RUNS]]
    assert min(drawn) in parsed and max(drawn) in parsed  # the extremes of the axis are among those parsed


def test_a_draw_refused_at_a_single_run_is_refused_before_anything_runs_naming_that_run():
    """Noise drawn around 0.008 with std 0.003: of 400 draws exactly one is negative (found by hand from the draws'
    definition); planning refuses it in one line naming that run and its value, as the parser refuses it alone."""
    seed, mean, std = 3, 0.008, 0.003
    noise = _noise_draws(seed, RUNS, mean, std)
    (bad,) = np.flatnonzero(noise < 0).tolist()  # the seed is chosen so that one draw of 400 is refused
    draws = [UNIFORM_M, {"target": "noise.theta", "distribution": "normal", "mean": mean, "std": std}]
    with pytest.raises(CampaignError) as err:
        plan_campaign(parse_campaign(_campaign(draws, seed=seed)))
    text = str(err.value)
    assert text.startswith(f"campaign: run {bad} (") and "\n" not in text, text
    assert f"noise.theta={noise[bad]:.4g}" in text and text.endswith("scenario: noise.theta must be >= 0.0"), text
    ok = _campaign([UNIFORM_M, {"target": "noise.theta", "distribution": "normal", "mean": mean, "std": std}], runs=bad)
    assert len(plan_campaign(parse_campaign(ok)).runs) == 2 * bad  # the draws before it are all accepted


@pytest.mark.parametrize("given", ["spec", "artifact"])
def test_a_reports_heads_name_each_run_as_the_run_made_alone(given, tmp_path):
    """What a report row names of each run (index, id, grid point, draw, values, seed, artifact), read from the plan
    without making any scenario, is what making the run gives: of a campaign designed per grid point, and of one
    given its artifact."""
    data = _campaign([UNIFORM_M, CHOICE_X], runs=50)
    if given == "artifact":
        designed = plan_campaign(parse_campaign(data))
        path = tmp_path / "gains.json"
        path.write_bytes(designed.artifacts[designed.runs[0].artifact_sha256])
        data.pop("spec")
        data.update(artifact=str(path), grid=[{"target": "initial_state.theta", "values": [0.0, 0.05]}])
    plan = plan_campaign(parse_campaign(data))
    heads = list(plan.runs.heads())
    assert len(heads) == len(plan.runs) == 100
    for head, point in zip(heads, plan.runs):
        assert (head.index, head.id, head.grid_index, head.draw, head.values, head.seed, head.artifact_sha256) == (
            point.index,
            point.id,
            point.grid_index,
            point.draw,
            point.values,
            point.seed,
            point.artifact_sha256,
        )
    assert [i.decode() for i in plan.runs.ids] == [p.id for p in plan.runs]
    assert not plan.runs.failed.any()


def _fmu_run(cart_fmu, pend, m: float):
    """A 1 s SIL run of the pendulum law on the cart-pendulum FMU (Co-Simulation), pole mass ``m``, with its twin."""
    return fmu_run(cart_fmu, pend, m, interface="cs", duration=1.0)


def test_an_fmu_instance_serves_a_workers_next_runs_as_a_fresh_one_would(cart_fmu, pend):
    """Inside reused_instances (as a campaign's worker runs), a run after another run of the FMU with other
    parameters gives the trace of the same run on fresh instances, bit for bit; over 6 runs the process holds the
    same instance (one a plant the run opens), one unzipped copy: instances are counted, not timed."""
    from gainlink.hil.plants import fmu

    fresh = _fmu_run(cart_fmu, pend, 0.12)
    assert not fmu.idle_instances()  # outside: each plant freed at its run's end
    with fmu.reused_instances():
        _fmu_run(cart_fmu, pend, 0.08)
        (kept,) = fmu.idle_instances().values()
        again = _fmu_run(cart_fmu, pend, 0.12)
        for _ in range(4):
            _fmu_run(cart_fmu, pend, 0.1)
            (now,) = fmu.idle_instances().values()
            assert sorted(map(id, now)) == sorted(map(id, kept))
    assert len(kept) == 1 and kept[0]._unzip is not None
    for name in ("t", "y", "u", "r"):
        assert np.array_equal(getattr(again.trace, name), getattr(fresh.trace, name)), name
    assert again.metrics["twin"] == fresh.metrics["twin"]


def _pendulum_task(runs: int) -> tuple:
    """The plan of ``runs`` draws of the shipped pendulum campaign (no anti-windup, 0.5 s) and its runs as a task
    carries them, run 1 naming a plant parameter the pendulum does not have (its record: an error)."""
    from gainlink.fileio import read_toml

    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    data |= {"runs": runs, "spec": str((path.parent / data["spec"]).resolve())}
    data["grid"][0]["values"] = ["none"]
    data["scenario"]["duration"] = 0.5
    plan = plan_campaign(parse_campaign(data))
    points = list(plan.runs)
    runs_ = [(p.artifact_sha256, dict(p.scenario), p.seed) for p in points]
    runs_[1][1]["plant"] = dict(runs_[1][1]["plant"], parameters={"mass": 2.0})
    return plan, points, runs_


def _stored(store) -> dict:
    """A folder's records (but what depends on the clock: the worker's pid and times, the loop's timing metrics),
    traces and whether each is a result, by run id."""
    from gainlink.hil.campaign.store import Store

    fresh = Store(store.out)  # read back from the files alone, as a resumed campaign reads them
    out = {}
    for i, rec in fresh.records():
        kept = {k: v for k, v in rec.items() if k not in ("worker", "metrics")}
        kept["metrics"] = (
            {k: rec["metrics"].get(k) for k in ("tracked", "outputs_final", "twin")} if "metrics" in rec else None
        )
        out[i] = (kept, fresh.trace(i), fresh.finished(i))
    return out


def test_a_worker_that_sees_the_campaign_folder_writes_its_block_and_one_that_does_not_returns_its_bytes(tmp_path):
    """A task of 4 pendulum runs (one an error) as the campaign submits it: a worker that sees the client's blocks
    folder (its device and inode) writes the block file there itself, 0644, no temporary file left, and answers a
    few numbers; a worker whose folder at the same path is another one (made again: another inode, as on another
    machine) writes nothing and returns the file's bytes, which the client writes. Both folders then hold the same
    records and traces, and the error's reason reaches the client either way."""
    import os
    import pickle

    from gainlink.hil.campaign.block_file import folder_key
    from gainlink.hil.campaign.block_layout import block_address
    from gainlink.hil.campaign.runner import _store_answer, plan_doc
    from gainlink.hil.campaign.store import Store
    from gainlink.hil.campaign.worker import execute_packed

    plan, points, runs = _pendulum_task(4)
    ids = [p.id for p in points]
    packed = pickle.dumps((ids, runs, None))
    answers, stores = {}, {}
    for side in ("sees", "elsewhere"):
        store = Store(tmp_path / side, campaign=plan.campaign.name)
        store.prepare(plan, plan_doc=plan_doc(plan))
        key = folder_key(store.blocks)
        if side == "elsewhere":  # the path names another folder now
            os.rename(store.blocks, tmp_path / side / "blocks-client")
            store.blocks.mkdir()
        answers[side] = execute_packed(
            "sil", plan.artifacts, packed, {}, campaign=plan.campaign.name, folder=(str(store.blocks), key)
        )
        stores[side] = store
    name = f"{block_address(ids)}.parquet"
    assert answers["sees"]["block"] == name and answers["sees"]["runs"] == 4
    assert [i for i, _ in answers["sees"]["errors"]] == [1]
    written = stores["sees"].blocks / name
    assert [p.name for p in stores["sees"].blocks.iterdir()] == [name]  # no temporary file left
    assert oct(written.stat().st_mode & 0o777) == "0o644"
    assert isinstance(answers["elsewhere"], bytes) and not list(stores["elsewhere"].blocks.iterdir())
    told = {side: _store_answer(stores[side], answers[side], ids) for side in answers}
    assert told["sees"] == told["elsewhere"]
    assert [r["status"] for r in told["sees"]] == ["done", "error", "done", "done"]
    assert "mass" in told["sees"][1]["reason"] and "\n" not in told["sees"][1]["reason"]
    assert stores["sees"].finished(ids[0]) and not stores["sees"].finished(ids[1]) and stores["sees"].has(ids[1])
    got, want = _stored(stores["sees"]), _stored(stores["elsewhere"])
    assert got.keys() == want.keys() == set(ids)
    for i in ids:
        assert got[i][0] == want[i][0] and got[i][2] == want[i][2]
        assert (got[i][1] is None) == (want[i][1] is None) == (i == ids[1])
        if got[i][1] is not None:
            assert all(np.array_equal(got[i][1][k], want[i][1][k]) for k in "tyur")


def test_a_block_keeping_some_traces_stores_only_theirs_and_its_metrics_from_the_column_trees(tmp_path, monkeypatch):
    """A task of one block (4 pendulum runs) told to keep runs 0 and 2's traces: the file holds theirs, each the trace
    the same task stores keeping every run's, and null for runs 1 and 3, the records otherwise the same; the metrics'
    columns come from the block's column trees either way (not the runs' dicts walked again)."""
    import pickle

    import gainlink.hil.campaign.block_file as block_file
    from gainlink.hil.campaign.block_file import folder_key
    from gainlink.hil.campaign.runner import _store_answer, plan_doc
    from gainlink.hil.campaign.store import Store
    from gainlink.hil.campaign.worker import execute_packed

    plan, points, runs = _pendulum_task(4)
    runs[1] = (points[1].artifact_sha256, dict(points[1].scenario), points[1].seed)  # no error: one block of 4
    ids = [p.id for p in points]
    paths: list[str] = []
    for name in ("tree_metric_columns", "metric_columns"):
        real = getattr(block_file, name)
        monkeypatch.setattr(block_file, name, lambda *a, _real=real, _name=name: paths.append(_name) or _real(*a))
    stored = {}
    for kept in (None, [True, False, True, False]):
        store = Store(tmp_path / str(kept is None), campaign=plan.campaign.name)
        store.prepare(plan, plan_doc=plan_doc(plan))
        answer = execute_packed(
            "sil", plan.artifacts, pickle.dumps((ids, runs, kept)), {}, campaign=plan.campaign.name,
            folder=(str(store.blocks), folder_key(store.blocks)),
        )  # fmt: skip
        _store_answer(store, answer, ids)
        stored[kept is None] = _stored(store)
    assert paths == ["tree_metric_columns", "tree_metric_columns"]
    every, some = stored[True], stored[False]
    assert every.keys() == some.keys() == set(ids)
    for k, i in enumerate(ids):
        assert every[i][0] == some[i][0] and every[i][2] and some[i][2]
        assert every[i][1] is not None and (some[i][1] is None) == (k in (1, 3))
        if k in (0, 2):
            assert all(np.array_equal(every[i][1][f], some[i][1][f]) for f in "tyur")


def test_a_task_runs_its_steps_outside_the_runs_without_cyclic_collection_and_leaves_the_collector_on(
    tmp_path, monkeypatch
):
    """A block's task (4 pendulum runs, one an error) groups its runs, stores them and writes its file with the cyclic
    garbage collector paused (each such collection walked the block's ~10^5 objects), and leaves the collector on
    after it, also when the task fails (bytes that are not a task)."""
    import gc
    import pickle

    import gainlink.hil.campaign.worker as worker
    from gainlink.hil.campaign.block_file import folder_key
    from gainlink.hil.campaign.runner import plan_doc
    from gainlink.hil.campaign.store import Store

    plan, points, runs = _pendulum_task(4)
    store = Store(tmp_path, campaign=plan.campaign.name)
    store.prepare(plan, plan_doc=plan_doc(plan))
    packed = pickle.dumps(([p.id for p in points], runs, None))
    collecting: dict[str, bool] = {}

    def spied(name: str):
        real = getattr(worker, name)

        def step(*args, **kwargs):
            collecting[name] = gc.isenabled()
            return real(*args, **kwargs)

        monkeypatch.setattr(worker, name, step)

    for name in ("_blocks", "encode_block", "write_block"):  # a task with an error: its records, not lists
        spied(name)
    assert gc.isenabled()
    answer = worker.execute_packed(
        "sil", plan.artifacts, packed, {}, campaign=plan.campaign.name,
        folder=(str(store.blocks), folder_key(store.blocks)),
    )  # fmt: skip
    assert answer["runs"] == 4 and collecting == {"_blocks": False, "encode_block": False, "write_block": False}
    assert gc.isenabled()
    with pytest.raises(pickle.UnpicklingError):
        worker.execute_packed("sil", plan.artifacts, b"not a task", {}, campaign=plan.campaign.name)
    assert gc.isenabled()
