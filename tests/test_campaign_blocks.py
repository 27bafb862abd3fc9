"""Campaign blocks: runs stepped together give each run what it gets alone, bit for bit.

Oracles: the plant alone (a batch of one) against the same plant in a block of hundreds with other parameters;
scipy's ``solve_ivp`` (a tight adaptive integrator) for the kernel's accuracy.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
from pathlib import Path

import numpy as np
import pytest
from gainlink.hil.plants.models import CartPendulum, OdeBatch, QuadrotorLateral, batchable
from gainlink.hil.plants.tank import Tank
from scipy.integrate import solve_ivp


def _draws(cls, count: int, rng: np.random.Generator, **fixed) -> list:
    """``count`` plants of ``cls`` with each default parameter scaled by a factor in [0.7, 1.3]."""
    plants = []
    for _ in range(count):
        params = {k: v * rng.uniform(0.7, 1.3) for k, v in cls.defaults.items()}
        plants.append(cls(parameters=params, **fixed))
    return plants


@pytest.mark.parametrize(
    "cls, start, command",
    [
        (CartPendulum, {"x": 1.0, "theta": 0.3}, 2.0),
        (QuadrotorLateral, {"phi": 0.2, "y": 1.0}, 0.01),
        (Tank, {"h": 0.5}, 0.3),
    ],
)
def test_a_block_steps_each_plant_as_it_steps_alone_bit_for_bit(cls, start, command):
    rng = np.random.default_rng(7)
    block, alone = _draws(cls, 300, rng, step=0.004), []
    for p in block:
        p.reset(initial=start)
    for p in block[::37]:  # the same parameters, stepped alone
        q = cls(parameters=p.params, step=0.004)
        q.reset(initial=start)
        alone.append(q)
    assert batchable(block)
    batch = OdeBatch(block)
    U = command * rng.standard_normal((60, len(block), 1))
    for k in range(60):
        Y = batch.outputs()
        for j, q in enumerate(alone):
            assert np.array_equal(Y[37 * j], q.outputs())  # bit for bit, not close
            q.advance(u=U[k, 37 * j], dt=0.01)
        assert not batch.advance(U[k], dt=0.01).any()
    for j, q in enumerate(alone):
        assert np.array_equal(batch.X[37 * j], q.state())


def test_the_kernel_integrates_the_pendulum_as_an_adaptive_solver_does():
    p = CartPendulum(parameters={"M": 1.2, "m": 0.15, "l": 0.45}, step=0.002)
    p.reset(initial={"theta": 0.4, "x": 0.5})
    x0 = p.state()
    for _ in range(50):
        p.advance(u=np.array([1.5]), dt=0.01)
    ref = solve_ivp(lambda t, x: _pendulum(x, 1.5, 1.2, 0.15, 0.45, 9.81), (0.0, 0.5), x0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(p.state(), ref.y[:, -1], rtol=0, atol=1e-9)


def _pendulum(x, F, M, m, l, g):
    """The cart pendulum's equations written out by hand (CartPendulum's docstring)."""
    s, c, w = np.sin(x[2]), np.cos(x[2]), x[3]
    D = M + m * s**2
    return [
        x[1],
        (F + m * l * w**2 * s - m * g * s * c) / D,
        w,
        ((M + m) * g * s - c * (F + m * l * w**2 * s)) / (l * D),
    ]


def _rk4_by_hand(x: list, F: float, P: dict, *, dt: float, h: float) -> list:
    """CartPendulum's docstring equations and classical RK4 in Python floats, every product and sum in the order
    written (sin and cos from math: libm's; the compiled kernel's are SLEEF's, within an ulp of them)."""
    M, m, l, g = P["M"], P["m"], P["l"], P["g"]

    def f(x):
        s, c, w = math.sin(x[2]), math.cos(x[2]), x[3]
        D = M + m * s * s
        return [x[1], (F + m * l * w * w * s - m * g * s * c) / D, w,
                ((M + m) * g * s - c * (F + m * l * w * w * s)) / (l * D)]  # fmt: skip

    n = max(1, int(np.ceil(dt / h - 1e-9)))
    hh = dt / n
    for _ in range(n):
        k1 = f(x)
        k2 = f([a + 0.5 * hh * b for a, b in zip(x, k1)])
        k3 = f([a + 0.5 * hh * b for a, b in zip(x, k2)])
        k4 = f([a + hh * b for a, b in zip(x, k3)])
        x = [a + (hh / 6.0) * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4)]
    return x


def test_the_block_kernel_is_the_pendulum_equations_and_rk4_written_out():
    """The batched kernel (its in-place buffers and parameter products taken once) steps as the equations written
    out in scalars, row by row, through 40 samples of random commands at random parameters. Tolerance 1e-12
    relative (atol 1e-15) over the 40 samples: the products and sums round alike, but the kernel's sin and cos
    (SLEEF's cinz u10) and libm's differ by an ulp on a few per cent of arguments."""
    rng = np.random.default_rng(12)
    plants = _draws(CartPendulum, 40, rng, step=0.004)
    for p in plants:
        p.reset(initial={"x": float(rng.normal()), "theta": float(rng.normal(0, 0.8)), "theta_dot": 1.0})
    batch = OdeBatch(plants)
    hand = [p.state().tolist() for p in plants]
    for _ in range(40):
        U = rng.normal(0.0, 8.0, (len(plants), 1))
        batch.advance(U, dt=0.01)
        hand = [_rk4_by_hand(x, float(u[0]), p.params, dt=0.01, h=0.004) for x, u, p in zip(hand, U, plants)]
        np.testing.assert_allclose(batch.X, np.array(hand), rtol=1e-12, atol=1e-15)


def test_a_row_that_blows_up_fails_alone_and_keeps_its_last_state():
    plants = [CartPendulum(step=0.005) for _ in range(3)]
    for p in plants:
        p.reset(initial={"theta": 0.1})
    batch = OdeBatch(plants)
    before = batch.X.copy()
    failed = batch.advance(np.array([[0.0], [1e308], [0.0]]), dt=0.01)
    assert failed.tolist() == [False, True, False]
    assert np.array_equal(batch.X[1], before[1])
    assert np.isfinite(batch.X).all()


def test_plants_of_other_kinds_or_steps_are_not_one_batch():
    assert not batchable([CartPendulum(step=0.005), CartPendulum(step=0.001)])
    assert not batchable([CartPendulum(), QuadrotorLateral()])


@pytest.mark.parametrize("numeric", ["float32", "q31"])
def test_one_c_call_steps_each_instance_as_its_own_native_step(numeric):
    """Row i of the block's answer equals instance i's own host C step (the per-run path's controller), bit for bit,
    through saturation and NaN samples (a FAULT)."""
    from gainlink.laws import law_of
    from support.fixed import example

    a = example("pendulum", numeric)
    law = law_of(a)
    count, steps = 7, 40
    rng = np.random.default_rng(3)
    Y = rng.normal(0.0, 0.6, (steps, count, a.p))
    Y[10, 2, 0] = np.nan
    Y[20:23, 5] = 40.0  # far out: saturates
    R = rng.normal(0.0, 0.2, (steps, count, a.q))
    S = np.zeros((steps, count, 0))
    block = law.native_block(a, count)
    alone = [law.native(a, library=block.host.library) for _ in range(count)]
    seen = set()
    for k in range(steps):
        got = block.step(Y[k], R[k], S[k])
        for i, c in enumerate(alone):
            want = c.step(Y[k, i], R[k, i], S[k, i])
            assert np.array_equal(got.u[i], want.u)
            assert (got.flags[i], got.sat[i]) == (want.flags, want.sat)
            seen |= {("fault", bool(want.flags & 1)), ("sat", bool(want.sat))}
    assert seen == {("fault", True), ("fault", False), ("sat", True), ("sat", False)}


def test_the_float64_law_over_a_block_is_each_runs_own_reference_bit_for_bit(random_designs):
    """Every form and anti-windup mode of the golden designs: each column of the block's float64 law equals that
    run's own reference (the per-run twin's controller), through saturation and refused (NaN) samples."""
    from gainlink.laws import law_of

    seen = set()
    for case in random_designs:
        a, law = case.artifact, law_of(case.artifact)
        count = 5
        block, alone = law.reference_block(a, count), [law.reference(a) for _ in range(count)]
        rng = np.random.default_rng(11)
        N = min(len(case.Y), 60)
        scale = rng.uniform(0.5, 8.0, count)  # the larger ones saturate
        for k in range(N):
            Y = case.Y[k] * scale[:, None] + rng.normal(0, 0.01, (count, a.p))
            R = np.tile(case.R[k], (count, 1))
            if k == 17:
                Y[3, 0] = np.nan
            got = block.step(Y, R, np.zeros((count, 0)))
            states = block.states()
            for i, c in enumerate(alone):
                want = c.step(Y[i], R[i], np.zeros(0))
                assert np.array_equal(got.u[i], want.u), case.label
                assert (got.flags[i], got.sat[i]) == (want.flags, want.sat), case.label
                assert np.array_equal(states[i], c.state()), case.label
                seen |= {("sat", bool(want.sat)), ("fault", bool(want.flags)), (a.observer_form, a.anti_windup)}
    assert {("sat", True), ("fault", True), ("current", "clamp"), ("predictor", "backcalc")} <= seen


# What a run alone and its run in a block must agree on: every control metric and verdict (timing is the call's).
CONTROL_KEYS = (
    "tracked", "outputs_final", "outputs_peak_abs", "inputs_peak_abs", "saturation_fraction", "saturated_steps",
    "peak_integrator", "twin", "steps", "complete", "refused_steps", "reason",
)  # fmt: skip
TRACE_FIELDS = ("t", "y", "r", "u", "sat", "flags", "sigma", "got", "x", "twin_y", "twin_u", "twin_z")


def _pendulum_campaign_points(draws: int, duration: float) -> tuple:
    """The shipped pendulum campaign (its three anti-windup modes) at ``draws`` draws of ``duration`` seconds: its
    artifacts and each run's parsed scenario."""
    from gainlink.fileio import read_toml
    from gainlink.hil.campaign import parse_campaign, worker
    from gainlink.hil.campaign.plan import plan_campaign
    from support.paths import EXAMPLES

    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    data |= {"runs": draws, "spec": str((path.parent / data["spec"]).resolve())}
    data["scenario"]["duration"] = duration
    plan = plan_campaign(parse_campaign(data))
    groups: dict = {}
    for p in plan.runs:
        art, where = worker.artifact_from_bytes(plan.artifacts[p.artifact_sha256])
        sc = worker._scenario(p.scenario, artifact_path=where, seed=p.seed, blobs={}, kind="sil")
        groups.setdefault(art.sha256, (art, []))[1].append(sc)
    return list(groups.values())


def _same_runs(draws: int, duration: float) -> int:
    from gainlink.hil.campaign.worker import _library
    from gainlink.hil.loop.block import run_block
    from gainlink.hil.loop.bridge import run_scenario

    compared = 0
    for art, scenarios in _pendulum_campaign_points(draws, duration):
        library = _library(art)
        for controller in ("firmware", "reference"):
            scs = [dataclasses.replace(sc, controller=controller) for sc in scenarios]
            block = run_block(scs, artifact=art, library=library)
            assert block is not None
            for sc, got in zip(scs, block):
                want = run_scenario(sc, artifact=art, library=library)
                for name in TRACE_FIELDS:
                    assert np.array_equal(getattr(got.trace, name), getattr(want.trace, name), equal_nan=True), name
                for key in CONTROL_KEYS:
                    assert got.metrics.get(key) == want.metrics.get(key), key
                assert got.complete == want.complete and got.reason == want.reason
                assert got.info["transport"] == want.info["transport"]
                compared += 1
    return compared


def test_the_pendulum_campaign_gives_each_run_through_a_block_what_it_gives_alone():
    """A few draws of the shipped campaign, its three anti-windup builds, the host C and the float64 law: every
    trace bit for bit, every control metric and verdict equal."""
    assert _same_runs(draws=6, duration=1.5) == 3 * 2 * 6


@pytest.mark.matrix
def test_the_pendulum_campaign_through_blocks_run_for_run_at_full_length():
    """300 runs of the shipped campaign (100 draws x 3 modes, 10 s each) with the host C and with the float64 law."""
    assert _same_runs(draws=100, duration=10.0) == 3 * 2 * 100


TIMING_KEYS = {"latency_us", "loop_cpu_s", "period_jitter_us", "steps_per_s", "twins_wall_s", "wall_s"}


def test_a_blocks_runs_with_and_without_a_model_twin_report_all_a_run_alone_reports():
    """A block of the campaign's draws, every other one with the model twin (the runs prepared like the block's
    first share what does not differ between them): each run's every metric but the timing (the model twin's
    figures and notes included), its artifact, plant and transport blocks and its model twin's trace equal what
    the run gives alone (run_scenario)."""
    from gainlink.hil.campaign.worker import _library
    from gainlink.hil.loop.block import run_block
    from gainlink.hil.loop.bridge import run_scenario

    art, scenarios = _pendulum_campaign_points(draws=6, duration=0.5)[0]
    scs = [dataclasses.replace(sc, model_twin=i % 2 == 1) for i, sc in enumerate(scenarios)]
    library = _library(art)
    block = run_block(scs, artifact=art, library=library)
    assert block is not None
    for sc, got in zip(scs, block):
        want = run_scenario(sc, artifact=art, library=library)
        assert got.metrics.keys() == want.metrics.keys()
        assert {k: v for k, v in got.metrics.items() if k not in TIMING_KEYS} == {
            k: v for k, v in want.metrics.items() if k not in TIMING_KEYS
        }
        assert ("model_twin" in got.metrics) == sc.model_twin
        for part in ("artifact", "plant", "transport"):
            assert got.info[part] == want.info[part], part
        for name in TRACE_FIELDS + ("model_y", "model_u"):
            a, b = getattr(got.trace, name), getattr(want.trace, name)
            assert (a is None and b is None) or np.array_equal(a, b, equal_nan=True), name


def _same_trace(got: dict, want: dict) -> bool:
    """Two records' stored traces (float32 arrays by name) are the same, bit for bit (NaN as NaN)."""
    return got["trace"].keys() == want["trace"].keys() and all(
        np.array_equal(got["trace"][k], want["trace"][k], equal_nan=True) for k in want["trace"]
    )


def test_a_task_steps_what_it_can_in_a_block_and_the_rest_alone_with_the_same_records(caplog):
    """A task of the campaign's runs: four pendulums that step as one block, two on linear plants (a block of their
    own), one with a nan fault and two on a user's pendulum that overrides ``advance`` without declaring itself
    vectorised (those three run alone); every record equals the run's own ``execute`` (control metrics, measures,
    traces), and each fallback is said once."""
    from gainlink.hil.campaign import worker

    plan, runs = _clamp_campaign(runs=9, duration=1.0)
    runs[4][1]["faults"] = [{"kind": "nan", "start": 0.2, "stop": 0.3}]
    for i in (5, 6):
        runs[i][1]["plant"] = {"kind": "linear"}
    for i in (7, 8):
        slow = {"kind": "python", "class": "support.campaign_plants:SlowPendulum", "pause": 0.0}
        runs[i][1]["plant"] = runs[i][1]["plant"] | slow
    with caplog.at_level(logging.INFO, logger="gainlink.hil.campaign.worker"):
        records = worker.batch_records("sil", plan.artifacts, runs)
    assert [r["status"] for r in records] == ["done"] * 9
    assert [r["worker"].get("block") for r in records] == [4, 4, 4, 4, None, 2, 2, None, None]
    for (sha, scenario, seed), got in zip(runs, records):
        want = worker.execute("sil", plan.artifacts[sha], scenario, seed)
        assert {k: got["metrics"].get(k) for k in CONTROL_KEYS} == {k: want["metrics"].get(k) for k in CONTROL_KEYS}
        assert (got["measures"], got["link"]) == (want["measures"], want["link"]) and _same_trace(got, want)
    lines = [r.getMessage() for r in caplog.records]
    assert sum("one by one" in line for line in lines) == 1
    assert sum("injects faults" in line for line in lines) == 1


def test_a_task_of_more_runs_than_step_in_lockstep_steps_them_in_parts_with_the_same_records(monkeypatch):
    """A task of 8 pendulum runs with at most 3 stepped in lockstep: parts of 2, 3 and 3 runs, in order (each run's
    ``worker.block`` its part's size), every run's record (metrics but the timing, measures, link, stored trace) the
    one it gets when the 8 step as one block; and the task's lists for its block file hold the parts' runs in task
    order, as their records do (the metrics as one column tree the parts' join, no dict a run), and the block file
    made from those lists is the one the records make (``encode_block``, the per-run path's), column by column."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from gainlink.hil.campaign import block_columns, block_file, worker

    plan, runs = _clamp_campaign(runs=8, duration=1.0)
    whole = worker.batch_records("sil", plan.artifacts, runs)
    monkeypatch.setattr(worker, "LOCKSTEP_RUNS", 3)
    assert [len(p) for p in worker.lockstep_parts(list(range(8)))] == [2, 3, 3]
    task = worker._task_records("sil", plan.artifacts, runs, None)
    parts = worker._materialized(task)
    assert [r["worker"]["block"] for r in whole] == [8] * 8
    assert [r["worker"]["block"] for r in parts] == [2, 2, 3, 3, 3, 3, 3, 3]
    assert len({id(b) for b in task}) == 3
    for got, want in zip(parts, whole):
        assert {k: v for k, v in got["metrics"].items() if k not in TIMING_KEYS} == {
            k: v for k, v in want["metrics"].items() if k not in TIMING_KEYS
        }
        keys = ("complete", "reason", "measures", "link")
        assert [got[k] for k in keys] == [want[k] for k in keys]
        assert _same_trace(got, want)
    lists = worker._block_runs("sil", runs, task)
    assert lists.measures == [r["measures"] for r in parts] and lists.metrics is None
    assert block_file._metrics_of(lists) == [r["metrics"] for r in parts]
    assert lists.worker == [r["worker"] for r in parts]
    assert [positions for positions, _ in lists.metric_trees] == [list(range(8))]  # the parts' trees joined
    assert block_columns.tree_named(lists.metric_trees, 8) is not None  # the typed columns straight from the tree
    ids = [f"run{i}" for i in range(8)]
    made = pq.read_table(pa.BufferReader(block_file.encode_runs(ids, lists, campaign="c")))
    records = [block_file.with_inputs(r, run, kind="sil") for r, run in zip(parts, runs)]
    oracle = pq.read_table(pa.BufferReader(block_file.encode_block(ids, records, campaign="c")))
    assert made.schema.equals(oracle.schema, check_metadata=True)
    for name in oracle.column_names:
        assert made.column(name).equals(oracle.column(name)), name


@pytest.mark.parametrize("Ts", [None, 0.02])
def test_linear_plants_step_in_a_block_as_alone_and_as_the_exact_discretisation(Ts):
    """Perturbed linear plants (continuous: sampled by the matrix exponential; discrete) in a block of 200 against
    each alone, bit for bit; and one of them against python-control's own discretisation and simulation."""
    import control
    from gainlink.hil.plants.linear import LinearBatch, LinearModel, LinearPlant, linear_batchable, perturb_model

    A = np.array([[0.0, 1.0, 0.0], [-2.0, -0.4, 1.0], [0.0, 0.0, -3.0]])
    B, C, D = (
        np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]]),
        np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
        np.zeros((2, 2)),
    )
    D[1, 0] = 0.3
    nominal = LinearModel(name="m", A=A, B=B, C=C, D=D, Ts=Ts, states=("a", "b", "c"), inputs=("u1", "u2"),
                          outputs=("y1", "y2"), u_op=np.array([0.5, -0.2]), y_op=np.array([1.0, 2.0]))  # fmt: skip
    rng = np.random.default_rng(5)
    plants = [LinearPlant(model=perturb_model(nominal, perturb={"A[1][0]": rng.uniform(-0.3, 0.3)},
                                               scale={"B": rng.uniform(0.8, 1.2)})) for _ in range(200)]  # fmt: skip
    for p in plants:
        p.reset(initial={"a": 0.4})
    alone = [LinearPlant(model=plants[i].model) for i in (0, 77, 199)]
    for q in alone:
        q.reset(initial={"a": 0.4})
    assert linear_batchable(plants)
    batch = LinearBatch(plants)
    U = rng.normal(0.0, 1.0, (80, len(plants), 2))
    Y0 = []
    for k in range(80):
        Y = batch.outputs()
        Y0.append(alone[0].outputs())
        for j, q in zip((0, 77, 199), alone):
            assert np.array_equal(Y[j], q.outputs())
            q.advance(u=U[k, j], dt=0.02)
        batch.advance(U[k], dt=0.02)
    sys = control.ss(plants[0].A, plants[0].B, C, D, Ts if Ts else 0)
    sysd = sys if Ts else control.c2d(sys, 0.02)
    x0 = np.array([0.4, 0.0, 0.0])
    du = U[:, 0] - nominal.u_op
    # y_k = y_op + C x_k + D du_{k-1}: the feed-through acts on the command held over the last sample
    resp = control.forced_response(control.ss(sysd.A, sysd.B, C, np.zeros((2, 2)), 0.02), U=du.T, X0=x0)
    want = nominal.y_op + resp.outputs.T + np.vstack([np.zeros(2), du[:-1] @ D.T])
    np.testing.assert_allclose(np.array(Y0), want, rtol=1e-10, atol=1e-12)


def _small_campaign_file(tmp_path, name: str):
    from support.paths import EXAMPLES

    path = tmp_path / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\nkind = "sil"\nseed = 1\nruns = 2\nspec = "{EXAMPLES / "pendulum.toml"}"\n'
        '[scenario]\nduration = 0.5\n[scenario.plant]\nkind = "cart_pendulum"\n'
        '[[draw]]\ntarget = "plant.parameters.M"\ndistribution = "uniform"\nlow = 0.7\nhigh = 1.3\n'
    )
    return path


@pytest.mark.parametrize(
    "plan, phrase",
    [
        ({"campaign": {"name": "other", "gainlink": "0.1.0"}, "runs": []}, "holds campaign 'other', not 'mine'"),
        ({"campaign": {"name": "mine"}, "runs": []}, "was written by gainlink older than 0.1.0"),
        ({"campaign": {"name": "mine", "gainlink": "9.9"}, "runs": []}, "was written by gainlink 9.9"),
        ("not json", "is not a campaign plan"),
    ],
)
def test_resuming_into_another_campaigns_or_versions_folder_is_refused_in_one_line(tmp_path, plan, phrase):
    import json

    from support.cli import assert_refused

    out = tmp_path / "out"
    out.mkdir()
    (out / "plan.json").write_text(plan if isinstance(plan, str) else json.dumps(plan))
    campaign = _small_campaign_file(tmp_path, "mine")
    assert_refused(["campaign", "run", campaign, "--out", out, "--workers", "1"], phrase, out)


def test_a_run_whose_plant_blows_up_ends_in_a_block_as_it_ends_alone():
    """One run of a block starts spinning at 1e200 rad/s: its plant (and its twin's) overflows in the first sample.
    It ends there with the reason a run alone gives, its twin off with the same note; the others run on."""
    from gainlink.hil.campaign.worker import _library
    from gainlink.hil.loop.block import run_block
    from gainlink.hil.loop.bridge import run_scenario

    art, scenarios = _pendulum_campaign_points(draws=3, duration=0.5)[0]
    scs = list(scenarios)
    scs[1] = dataclasses.replace(scs[1], initial_state={"theta_dot": 1e200})
    library = _library(art)
    block = run_block(scs, artifact=art, library=library)
    alone = [run_scenario(sc, artifact=art, library=library) for sc in scs]
    assert [r.complete for r in block] == [True, False, True]
    assert block[1].reason == alone[1].reason and "plant failed at step 0" in block[1].reason
    assert block[1].metrics.get("twin_off") == alone[1].metrics.get("twin_off") is not None
    for got, want in zip(block, alone):
        for name in TRACE_FIELDS:
            assert np.array_equal(getattr(got.trace, name), getattr(want.trace, name), equal_nan=True), name
        assert {k: got.metrics.get(k) for k in CONTROL_KEYS} == {k: want.metrics.get(k) for k in CONTROL_KEYS}


def test_a_bad_run_in_a_block_costs_no_other_its_result(caplog):
    """One run of a task names a parameter its plant does not have: it is left out of its block and runs alone,
    recording its one-line error; the others still step as a block, with the records they get alone."""
    from gainlink.fileio import read_toml
    from gainlink.hil.campaign import parse_campaign, worker
    from gainlink.hil.campaign.plan import plan_campaign
    from support.paths import EXAMPLES

    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    data |= {"runs": 3, "spec": str((path.parent / data["spec"]).resolve())}
    data["grid"][0]["values"] = ["none"]
    data["scenario"]["duration"] = 0.5
    plan = plan_campaign(parse_campaign(data))
    runs = [(p.artifact_sha256, dict(p.scenario), p.seed) for p in plan.runs]
    plant = dict(runs[1][1]["plant"])
    plant["parameters"] = dict(plant["parameters"], mass=2.0)
    runs[1][1]["plant"] = plant
    with caplog.at_level(logging.INFO, logger="gainlink.hil.campaign.worker"):
        records = worker.batch_records("sil", plan.artifacts, runs)
    assert [r["status"] for r in records] == ["done", "error", "done"]
    assert [r["worker"].get("block") for r in records] == [2, None, 2]
    assert ["run 1 of this task runs alone: its plant could not be built" in r.getMessage()
            for r in caplog.records] == [True]  # fmt: skip
    assert "no parameter 'mass'" in records[1]["reason"] and "\n" not in records[1]["reason"]
    for i in (0, 2):
        want = worker.execute("sil", plan.artifacts[runs[i][0]], runs[i][1], runs[i][2])
        assert _same_trace(records[i], want) and records[i]["measures"] == want["measures"]


def test_each_instance_of_a_block_runs_its_own_gain_set():
    """Instances 1 and 2 of a block stage gain sets of their own (K and Ki retuned two ways): each row answers as a
    host C loop alone with that set staged, bit for bit, and the instance left on the built-in set as one on it."""
    from gainlink.engines.native import NativeLoop
    from gainlink.firmware.host import HostLawBlock
    from support.fixed import example

    a = example("pendulum", "float32")
    block = HostLawBlock(a, 3)
    alone = [NativeLoop(a, library=block.library) for _ in range(3)]
    for i, (k, ki) in enumerate(((1.1, 0.9), (0.8, 1.2)), start=1):
        gains = alone[i].default_gains()
        gains.K[0][2] *= k
        gains.Ki[0][0] *= ki
        gains.crc32 = alone[i].crc32(gains)
        assert alone[i].stage(gains) == 0 and block.stage(i, gains) == 0
    rng = np.random.default_rng(2)
    differ = 0
    for _ in range(50):  # the same samples to every instance: only their gains tell them apart
        Y, R = np.tile(rng.normal(0, 0.05, a.p), (3, 1)), np.tile(rng.normal(0, 0.02, a.q), (3, 1))
        rec = block.step(Y, R)
        for i, c in enumerate(alone):
            want = c.step(Y[i], R[i])
            assert np.array_equal(rec["u"][i], want.u.astype(np.float32))
        differ += len(set(rec["u"][:, 0].tolist())) == 3
    assert differ >= 45  # the three sets answer differently


@pytest.mark.parametrize(
    "meta, phrase",
    [
        ({"gainlink.campaign": "other", "gainlink.version": "0.1.0"}, "holds campaign 'other', not 'mine'"),
        ({"gainlink.campaign": "mine", "gainlink.version": "9.9"}, "was written by gainlink 9.9"),
        ({"gainlink.campaign": "mine", "gainlink.version": "0.1.0"}, "is a block file of an earlier layout"),
        (None, "holds per-run results (runs/) of an earlier gainlink"),
        ("not parquet", "is not a block file this gainlink can read"),
    ],
)
def test_resuming_into_a_folder_with_foreign_blocks_is_refused_in_one_line(tmp_path, meta, phrase):
    """The folder's plan is this campaign's, but one of its block files (or its layout) is not: refused before
    anything is written."""
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq
    from gainlink.hil.campaign.block_file import encode_block
    from gainlink.version import __version__
    from support.cli import assert_refused

    out = tmp_path / "out"
    (out / "blocks").mkdir(parents=True)
    (out / "plan.json").write_text(json.dumps({"campaign": {"name": "mine", "gainlink": __version__}, "runs": []}))
    block = out / "blocks" / "0123456789abcdef01234567.parquet"
    if meta is None:
        (out / "runs").mkdir()
    elif isinstance(meta, str):
        block.write_text(meta)
    else:
        data = encode_block(["x"], [{"status": "error", "reason": "r"}], campaign="mine")
        table = pq.read_table(pa.BufferReader(data))
        pq.write_table(table.replace_schema_metadata({k.encode(): v.encode() for k, v in meta.items()}), block)
    campaign = _small_campaign_file(tmp_path, "mine")
    assert_refused(["campaign", "run", campaign, "--out", out, "--workers", "1"], phrase, out)


@pytest.mark.parametrize(
    "plan, phrase",
    [
        ({"campaign": {"name": "mine"}, "run_ids": ["abc123"]}, "run abc123 has no record yet"),
        ({"campaign": {"name": "mine"}, "runs": [{"id": "abc123"}]}, "is not a campaign plan this gainlink can read"),
    ],
)
def test_show_refuses_a_run_without_a_record_and_a_plan_of_an_earlier_layout_in_one_line(tmp_path, plan, phrase):
    import json

    from support.cli import assert_refused

    out = tmp_path / "out"
    out.mkdir()
    (out / "plan.json").write_text(json.dumps(plan))
    assert_refused(["campaign", "show", out, "--run", "abc", "--report", tmp_path / "r"], phrase, out, tmp_path)


@pytest.mark.parametrize("width, dtype", [((3,), float), ((), np.int64), ((2, 2), float)])
@pytest.mark.parametrize("steps, taken", [(150, 150), (150, 129), (64, 64), (10, 3), (0, 0)])
def test_a_blocks_record_is_each_runs_rows_in_step_order(steps, taken, width, dtype):
    """Rows written a step at a time (moved run-major a chunk at a time, each record as one item of its bytes) read
    back as each run's own rows, up to the step the block stopped at, whatever the chunk boundaries and the
    record's shape."""
    from gainlink.hil.loop.block import _RunMajor

    rng = np.random.default_rng(9)
    rows = (rng.normal(size=(steps, 7, *width)) * 1e6).astype(dtype)
    record = _RunMajor(steps, 7, width, dtype)
    for k in range(taken):
        record.at(k)[:] = rows[k]
    got = record.taken(taken)
    assert np.array_equal(got, rows[:taken].swapaxes(0, 1))
    assert all(got[i].flags.c_contiguous for i in range(7))


def test_a_blocks_runs_are_parsed_and_planned_once_as_each_alone():
    """A task's runs of one mode differ only in their draws and seeds: ``_blocks`` parses the first and gives the
    others its scenario with their own numbers, each equal to its own full parse (the oracle: ``parse_scenario`` of
    its table); ``prepare_block`` plans the first and gives the others its plan with their own noise, each equal to
    its own ``plan_run``. A run whose table differs elsewhere (another noise level) is parsed and planned alone."""
    from gainlink.hil.campaign import worker
    from gainlink.hil.loop.block import prepare_block
    from gainlink.hil.loop.bridge import build_plant
    from gainlink.hil.loop.plan import plan_run
    from gainlink.laws import law_of

    plan, runs = _clamp_campaign(runs=5, duration=0.5)
    runs[3][1]["noise"] = {"x": 0.002, "theta": 0.0005}
    (members,) = worker._blocks(plan.artifacts, runs, {}).values()
    assert [i for i, _, _ in members] == [0, 1, 2, 3, 4]
    for (_, art, got), (_, scenario, seed) in zip(members, runs):
        want = worker._scenario(scenario, artifact_path=_artifact_file(art), seed=seed, blobs={}, kind="sil")
        assert got == want
    assert len({sc.plant["parameters"]["M"] for _, _, sc in members}) == 5
    art, scs = members[0][1], [sc for _, _, sc in members]
    law = law_of(art)
    runs_ = prepare_block(scs, law=law, artifact=art, plants=[build_plant(sc, artifact=art) for sc in scs])
    for sc, run in zip(scs, runs_):
        plant = build_plant(sc, artifact=art)
        plant.reset(initial=sc.initial_state)
        want = plan_run(sc, law=law, artifact=art, plant=plant)
        for name in ("t", "R", "noise", "D", "S"):
            assert np.array_equal(getattr(run.plan, name), getattr(want, name)), name
        assert (run.plan.N, run.plan.period_s) == (want.N, want.period_s)
    assert runs_[1].plan.R is runs_[0].plan.R and runs_[3].plan.R is not runs_[0].plan.R
    assert not np.array_equal(runs_[1].plan.noise, runs_[2].plan.noise)


def _artifact_file(artifact):
    from gainlink.hil.campaign import worker

    return worker._ARTIFACTS[artifact.sha256][1]


def _design(name: str):
    """The artifact of the block column tests' ``design``: the shipped pendulum, a regulator (no tracked output) or a
    random design tracking two references."""
    from support.fixed import example, random_design

    if name == "pendulum":
        return example("pendulum", "float32")
    if name == "regulator":
        return random_design(4, "float32", n=3, m=2, p=2, q=0)
    return random_design(5, "float32", n=4, m=2, p=3, q=2)


def _traces(a, rng: np.random.Generator, lengths: list[int]) -> list:
    """Runs of ``a`` with the cases a block's metrics must get right: references that step at different samples
    (and never), an error of zero at the start (regulation), saturation, refused steps, NaN samples, runs with and
    without a twin (one with non-finite integrators), runs of other lengths (0, 1, 2 steps)."""
    from gainlink.hil.loop.metrics import RunTrace

    traces = []
    for i, n in enumerate(lengths):
        t = np.arange(n) * a.Ts
        y = rng.normal(0.0, 0.3, (n, a.p)) + np.linspace(1.0, 0.0, n)[:, None] * rng.uniform(-2, 2, a.p)
        r = np.zeros((n, a.q))
        if a.q and i % 3:
            r[rng.integers(0, max(n, 1)) :] = rng.normal(0.0, 1.0, a.q)  # one step, somewhere
        if a.q and i % 5 == 0 and n:
            y[:] = r @ a.Ci + 0.0  # nothing to track: regulation with zero error
        if i % 7 == 3 and n:
            y[rng.integers(0, n), 0] = np.nan
        u = rng.normal(0.0, 1.0, (n, a.m))
        sat = rng.random((n, a.m)) < 0.2
        twin = i % 4 != 1
        twin_z = rng.normal(0.0, 0.5, (n, a.q)) if twin else np.full((n, a.q), np.nan)
        if i % 11 == 2 and n:
            twin_z[0, :] = np.inf
        twin_y = y + rng.normal(0.0, 1e-3, y.shape) if twin else np.full(y.shape, np.nan)
        twin_u = u + rng.normal(0.0, 1e-3, u.shape) if twin else np.full(u.shape, np.nan)
        if i % 9 in (4, 6) and n:  # a NaN command or sample its finite twin does not share: a NaN relative figure,
            hit = u if i % 9 == 4 else y  # first or later in its row
            hit[rng.integers(0, n), (i // 9) % hit.shape[1]] = np.nan
        traces.append(RunTrace(
            t=t, y=y, r=r, s=np.zeros((n, 0)), u=u, sat=sat, got=rng.random(n) < 0.95,
            latency_ns=np.full(n, 1e3), tick_ns=t * 1e9, deadline_ns=np.full(n, np.nan), x=np.full((n, 2), np.nan),
            flags=np.where(rng.random(n) < 0.1, 1, 0), sigma=np.full(n, np.nan), nan_sent=np.zeros(n, dtype=bool),
            twin_y=twin_y, twin_u=twin_u, twin_z=twin_z,
        ))  # fmt: skip
    return traces


@pytest.mark.parametrize("design", ["pendulum", "regulator", "two_references"])
def test_a_blocks_metrics_as_columns_are_each_runs_own_compute_metrics(design):
    """block_metrics over 197 runs of mixed lengths and cases (137 of one length: reduced in two parts) equals
    compute_metrics of each run (the per-run function, the oracle), every figure exactly: no figure needed a
    tolerance."""
    from gainlink.hil.loop.block_metrics import RUNS_AT_ONCE, block_metrics
    from gainlink.hil.loop.metrics import compute_metrics

    a = _design(design)
    rng = np.random.default_rng(21)
    lengths = [50] * 40 + [37] * 15 + [0, 1, 1, 2, 2] + [20] * (RUNS_AT_ONCE + 9)  # the last: more than one part
    traces = _traces(a, rng, lengths)
    timed = [{"latency_us": {"p50": 1.0}, "period_jitter_us": {"p50": None}}] * len(traces)
    got = block_metrics(traces, artifact=a, mode="sil", late=0, period_s=[a.Ts] * len(traces),
                        model_start=[""] * len(traces), timed=timed)  # fmt: skip
    seen = set()
    for tr, g, tm in zip(traces, got, timed):
        want = compute_metrics(tr, artifact=a, mode="sil", late=0, period_s=a.Ts, timed=tm)
        assert g == want
        assert list(g) == list(want)  # the same order of keys
        for v in want["tracked"].values():
            seen |= {("overshoot", v["overshoot_pct"] is None), ("settled", v["settling_time_s"] is not None)}
        seen |= {("twin", "twin" in want), ("integrator", "peak_integrator" in want)}
    assert {("twin", True), ("twin", False), ("settled", True), ("overshoot", False)} <= seen
    if a.q:
        assert {("overshoot", True), ("settled", False), ("integrator", True)} <= seen


@pytest.mark.parametrize("design", ["pendulum", "regulator", "two_references"])
def test_a_blocks_metrics_columns_from_its_column_trees_are_those_of_its_runs_dicts(design):
    """The block file's metrics columns made from the block's column trees (one tree a structure of the runs' dicts:
    with a twin or not, integrator peaks or not; runs of several lengths and groups joined) are those the runs' dicts
    make (block_columns.metric_columns, itself checked against json's text), every column equal; runs of no steps leave
    the trees unusable for that (their dicts held whole) and the worker then takes the dicts."""
    from gainlink.hil.campaign.block_columns import metric_columns, tree_metric_columns
    from gainlink.hil.loop.block_metrics import RUNS_AT_ONCE, metric_trees

    a = _design(design)
    rng = np.random.default_rng(33)
    for lengths, columnar in (([50] * 40 + [37] * 15 + [20] * (RUNS_AT_ONCE + 9), True), ([50] * 9 + [0, 2], False)):
        traces = _traces(a, rng, lengths)
        timed = [{"latency_us": {"p50": 1.0}, "period_jitter_us": {"p50": None}}] * len(traces)
        trees = metric_trees(traces, artifact=a, mode="sil", late=0, period_s=[a.Ts] * len(traces),
                             model_start=[""] * len(traces), timed=timed)  # fmt: skip
        rows = trees.rows()
        assert trees.columnar == columnar
        assert sorted(i for positions, _ in trees.trees for i in positions) == list(range(len(traces)))
        if columnar:
            assert len(trees.trees) > 1  # runs of more than one structure
            made, oracle = tree_metric_columns(trees.trees, len(rows)), metric_columns(rows)
            assert list(made) == list(oracle)
            for name in oracle:
                assert made[name].equals(oracle[name]), name


def test_an_arrays_address_is_numpys_own_whatever_its_layout():
    """lockstep.address (what the C is handed and what block_metrics.stacked compares) equals numpy's own
    ``__array_interface__`` address for the arrays a block hands over: contiguous rows, strided and reversed views,
    a law state's column, read-only plan arrays, empty and 0-d arrays."""
    from gainlink.hil.loop.lockstep import address

    A, L = np.zeros((4, 5, 6)), np.zeros((3, 7, 5))
    frozen = A.copy()
    frozen.flags.writeable = False
    cases = [A[1], A[1, 2:], A[:, 1], A[1][::-1], A[1][:, ::-1], A[..., 2], L[1, :, 4:5], L[2, :, 1:3], frozen[2],
             frozen[:, 3], np.zeros(0), np.zeros((3, 0)), np.zeros(()),
             np.broadcast_to(A[0], (3, 5, 6))[2]]  # fmt: skip
    for a in cases:
        assert address(a) == a.__array_interface__["data"][0], (a.shape, a.strides)


def _as_block(traces: list, step_at: int | None, rng: np.random.Generator) -> list:
    """``traces`` (runs of one length) laid out as a block's: each run's arrays rows of one run-major record, every
    run reading one shared reference array (a plan's: a step at ``step_at``, or constant) and one array of the steps
    answered in time."""
    n, q = traces[0].t.size, traces[0].r.shape[1]
    shared = np.zeros((n, q)) + rng.normal(0.0, 0.5, q)
    if step_at is not None:
        shared[step_at:] += rng.normal(0.0, 1.0, q)
    shared.flags.writeable = False
    got = rng.random(n) < 0.9  # one array every run reads, as a block's runs share theirs
    record = {name: np.stack([getattr(tr, name) for tr in traces]) for name in ("y", "u", "twin_y", "twin_u", "twin_z")}
    return [dataclasses.replace(tr, r=shared, t=traces[0].t, got=got[:], **{k: v[i] for k, v in record.items()})
            for i, tr in enumerate(traces)]  # fmt: skip


@pytest.mark.parametrize("design", ["pendulum", "regulator", "two_references"])
@pytest.mark.parametrize("step_at", [None, 0, 1, 23, 49])
def test_a_blocks_columns_over_its_record_and_a_shared_reference_are_each_runs_own(design, step_at):
    """The block's own layout (each run's rows views of one record, one reference array all its runs share: the
    columns' shared-start path, the traces' one gather) in blocks of 1 and 30 runs: block_metrics, measure_block and
    downsampled_traces equal compute_metrics, measure and each run's own samples (the per-run functions, the
    oracles), every figure exactly; NaN samples, non-finite integrators, runs without a twin and a regulation that
    starts at its set point included (_traces)."""
    from types import SimpleNamespace

    from gainlink.hil.campaign.criteria import measure, measure_block
    from gainlink.hil.campaign.worker import downsampled_trace, downsampled_traces
    from gainlink.hil.loop.block_metrics import block_metrics
    from gainlink.hil.loop.metrics import compute_metrics

    a = _design(design)
    rng = np.random.default_rng(57 + (step_at or 0))
    for runs in (1, 30):
        traces = _as_block(_traces(a, rng, [50] * runs), step_at, rng)
        if a.q:  # the first run at its set point from its start: nothing to track
            traces[0].y[:] = traces[0].r @ a.Ci + 0.0
        timed = [{"latency_us": {"p50": 1.0}, "period_jitter_us": {"p50": None}}] * runs
        got = block_metrics(traces, artifact=a, mode="sil", late=0, period_s=[a.Ts] * runs,
                            model_start=[""] * runs, timed=timed)  # fmt: skip
        results = [SimpleNamespace(trace=tr, complete=i % 7 != 3, reason=None, metrics=m)
                   for i, (tr, m) in enumerate(zip(traces, got))]  # fmt: skip
        measured = measure_block(results, a)
        stored = downsampled_traces(traces)
        for tr, g, result, mg, d in zip(traces, got, results, measured, stored):
            want = compute_metrics(tr, artifact=a, mode="sil", late=0, period_s=a.Ts, timed=timed[0])
            assert g == want and list(g) == list(want)
            assert mg == measure(result, a)
            alone = downsampled_trace(dataclasses.replace(tr, **{k: getattr(tr, k).copy() for k in "tyur"}))
            for k in "tyur":
                assert d[k].dtype == np.float32 and d[k].flags.c_contiguous
                assert d[k].shape == alone[k].shape and np.array_equal(d[k], alone[k], equal_nan=True), k


def test_a_scheduled_laws_block_records_each_runs_sigma_as_alone():
    """The scheduled tank (sigma: its measured level) in a block of four runs of other orifice coefficients and
    seeds, the host C and the float64 law: each run's trace (its sigma included, recorded because this law has one)
    equals the run's own, bit for bit."""
    import copy

    from gainlink.hil.campaign.worker import _library
    from gainlink.hil.loop.block import run_block
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import parse_scenario
    from gainlink.shipping.artifact import from_dict
    from schedule_cases import tank_dict, tank_hil_scenario
    from support.designs import designed

    art = from_dict(designed(tank_dict()))
    base = tank_hil_scenario("unused.json", name="tank", transport={}, duration=0.5, noise={"h": 1e-3})
    library = _library(art)
    for controller in ("firmware", "reference"):
        scs = []
        for i, c in enumerate((0.4, 0.36, 0.44, 0.41)):
            data = copy.deepcopy(base) | {"seed": 10 + i, "controller": controller}
            data["plant"]["parameters"] = {"c": c}
            scs.append(parse_scenario(data))
        block = run_block(scs, artifact=art, library=library)
        assert block is not None and all(r is not None for r in block)
        for sc, got in zip(scs, block):
            want = run_scenario(sc, artifact=art, library=library)
            assert np.isfinite(want.trace.sigma).all()
            for name in TRACE_FIELDS:
                assert np.array_equal(getattr(got.trace, name), getattr(want.trace, name), equal_nan=True), name
            assert {k: got.metrics.get(k) for k in CONTROL_KEYS} == {k: want.metrics.get(k) for k in CONTROL_KEYS}


def test_a_block_whose_runs_differ_in_disturbances_gives_each_what_it_gets_alone():
    """One run of three pushes the cart (a 3 N input disturbance for 0.2 s), the others do not: that run is planned
    alone and its command goes to its plant with the push, the others' without, each trace as alone bit for bit."""
    from gainlink.hil.campaign.worker import _library
    from gainlink.hil.loop.block import run_block
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import Disturbance

    art, scenarios = _pendulum_campaign_points(draws=3, duration=0.5)[0]
    scs = list(scenarios)
    scs[1] = dataclasses.replace(scs[1], disturbances=(Disturbance(input="F", start=0.1, stop=0.3, value=3.0),))
    library = _library(art)
    block = run_block(scs, artifact=art, library=library)
    alone = [run_scenario(sc, artifact=art, library=library) for sc in scs]
    for got, want in zip(block, alone):
        for name in TRACE_FIELDS:
            assert np.array_equal(getattr(got.trace, name), getattr(want.trace, name), equal_nan=True), name
        assert {k: got.metrics.get(k) for k in CONTROL_KEYS} == {k: want.metrics.get(k) for k in CONTROL_KEYS}


def _clamp_campaign(*, runs: int, duration: float):
    """The shipped pendulum campaign's clamp mode, ``runs`` draws of ``duration`` seconds: its plan and the runs as a
    task gets them (artifact sha256, scenario, seed)."""
    from gainlink.fileio import read_toml
    from gainlink.hil.campaign import parse_campaign
    from gainlink.hil.campaign.plan import plan_campaign
    from support.paths import EXAMPLES

    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    data |= {"runs": runs, "spec": str((path.parent / data["spec"]).resolve())}
    data["grid"][0]["values"] = ["clamp"]
    data["scenario"]["duration"] = duration
    plan = plan_campaign(parse_campaign(data))
    return plan, [(p.artifact_sha256, dict(p.scenario), p.seed) for p in plan.runs]


@pytest.mark.parametrize("design", ["pendulum", "regulator", "two_references"])
def test_a_blocks_measures_and_downsampled_traces_as_columns_are_each_runs_own(design):
    """measure_block over 300 runs (mixed lengths: 0 to 1,300 steps; NaN samples, growing and decaying errors,
    saturation, runs that did not complete, with and without twins) equals measure of each run (the per-run
    function, the oracle), every figure exactly; downsampled_traces gives each run its samples at the evenly
    spaced indices (first and last kept, at most 600) as float32."""
    from types import SimpleNamespace

    from gainlink.hil.campaign.criteria import measure, measure_block
    from gainlink.hil.campaign.worker import MAX_TRACE_POINTS, downsampled_traces
    from gainlink.hil.loop.metrics import compute_metrics

    a = _design(design)
    rng = np.random.default_rng(33)
    lengths = [60] * 240 + [1300] * 40 + [0, 0, 1, 5, 7, 8, 9, 37, 37] + [2] * 11
    traces = _traces(a, rng, lengths)
    results = []
    for i, tr in enumerate(traces):
        if i % 6 == 4:  # an error that grows in the last quarter (unstable), or a run all NaN in one output
            tr.y[:] *= np.linspace(0.1, 3.0, tr.t.size)[:, None] ** 4
        if i % 53 == 5:
            tr.y[:, -1] = np.nan
        metrics = compute_metrics(tr, artifact=a, mode="sil", late=0, period_s=a.Ts, timed=None)
        if i % 3 == 0:
            metrics["model_twin"] = {"worst": 0.1 * i, "iae": {"e": {"ratio": 1.0 + i}, "f": {"ratio": None}},
                                     "warning": i % 2 == 0}  # fmt: skip
        complete = i % 13 != 6
        reason = None if complete or i % 2 else f"plant failed at step {i}"
        results.append(SimpleNamespace(trace=tr, complete=complete, reason=reason, metrics=metrics))
    got = measure_block(results, a)
    seen = set()
    for result, g in zip(results, got):
        want = measure(result, a)
        assert g == want
        assert list(g) == list(want)
        seen |= {("stable", want["stable"]), ("grows", "grows" in str(want["unstable_reason"])),
                 ("saturated", want["longest_saturation_s"] > 0),
                 ("none_min", None in want["output_min"].values())}  # fmt: skip
    assert seen >= {("stable", True), ("stable", False), ("grows", True), ("saturated", True), ("none_min", True)}
    stepped = [tr for tr in traces if tr.t.size]  # a run of no steps has no trace to store
    for tr, d in zip(stepped, downsampled_traces(stepped)):
        n = tr.t.size
        idx = np.unique(np.round(np.linspace(0, n - 1, min(n, MAX_TRACE_POINTS))).astype(int))
        assert idx.size <= MAX_TRACE_POINTS and (idx[0], idx[-1]) == (0, n - 1)
        for k, width in (("t", None), ("y", a.p), ("u", a.m), ("r", a.q)):
            want = getattr(tr, k)[idx].astype(np.float32)
            assert d[k].dtype == np.float32 and d[k].flags.c_contiguous
            assert np.array_equal(d[k], want if width is None else want.reshape(idx.size, width), equal_nan=True)


def _pendulum_form(form: str, anti_windup: str):
    """The shipped pendulum design (examples/pendulum.toml, the campaign's spec) with observer ``form`` and
    ``anti_windup`` mode."""
    import copy

    from gainlink.fileio import read_toml
    from gainlink.shipping.artifact import from_dict
    from support.designs import designed
    from support.paths import EXAMPLES

    data, _ = read_toml(EXAMPLES / "pendulum.toml", what="spec", error=ValueError)
    data = copy.deepcopy(data)
    data["observer"]["form"], data["limits"]["anti_windup"] = form, anti_windup
    return from_dict(designed(data))


@pytest.mark.parametrize("form", ["predictor", "current"])
def test_the_compiled_float64_law_is_each_runs_own_python_reference_bit_for_bit(form):
    """The twin's law in one C call per step (law.reference_block) against each instance's own Python reference
    (law.reference: the per-run twin's law) and the Python columns (ReferenceBlock): the shipped pendulum design
    in each anti-windup mode, 41 instances (not a multiple of any vector width) through saturation, refused (NaN)
    samples, a reference shared by every run (a row stride of 0) and references of their own; every command, flag,
    saturation mask and state equal, bit for bit."""
    from gainlink.laws import law_of
    from gainlink.laws.lq.block import ReferenceBlock
    from gainlink.laws.lq.native_block import NativeReferenceBlock

    seen = set()
    for mode in ("none", "clamp", "backcalc"):
        a = _pendulum_form(form, mode)
        law, count = law_of(a), 41
        block, columns = law.reference_block(a, count), ReferenceBlock(a, count)
        assert isinstance(block, NativeReferenceBlock)
        alone = [law.reference(a) for _ in range(count)]
        rng = np.random.default_rng(7)
        scale = rng.uniform(0.2, 30.0, count)  # the larger ones saturate
        for k in range(80):
            Y = rng.normal(0.0, 0.05, (count, a.p)) * scale[:, None]
            if k % 2:
                R = np.broadcast_to(rng.normal(0.0, 1.0, (1, a.q)), (count, a.q))  # shared: stride 0
            else:
                R = rng.normal(0.0, 1.0, (count, a.q))
            if k in (17, 50):
                Y[3, 0], Y[40, 1] = np.nan, np.inf
            got, ref = block.step(Y, R, np.zeros((count, 0))), columns.step(Y, R, np.zeros((count, 0)))
            states = block.states()
            assert np.array_equal(got.u, ref.u) and np.array_equal(got.sat, ref.sat)
            assert np.array_equal(got.flags, ref.flags) and np.array_equal(states, columns.states())
            for i, c in enumerate(alone):
                want = c.step(Y[i], R[i], np.zeros(0))
                assert np.array_equal(got.u[i], want.u), (mode, k, i)
                assert (got.flags[i], got.sat[i]) == (want.flags, want.sat), (mode, k, i)
                assert np.array_equal(states[i], c.state()), (mode, k, i)
                seen |= {(mode, "sat", bool(want.sat)), (mode, "fault", bool(want.flags))}
    assert {(m, w, b) for m in ("none", "clamp", "backcalc") for w in ("sat", "fault") for b in (True, False)} <= seen


STEPS_FIELDS = ("Y", "U", "sat", "flags", "sigma", "X", "L", "steps", "failed_at")


def _block_inputs(art, scenarios: list, *, twin: bool, library=None, blows=(8,), mid: int = 6):
    """A block's runs prepared as ``run_block`` prepares them (fresh plants and laws) with what a campaign rarely
    gives but a block must step alike: NaN and +-inf noise samples (run 2), references of its own (run 4, the others
    sharing one array), a disturbance that blows its plant up mid-run (run ``mid``) and plants that blow up in their
    first sample (the runs ``blows``), each when the block has that run; the controller the run (or its twin) steps
    with."""
    import dataclasses as dc

    from gainlink.hil.loop.block import batch_of, prepare_block
    from gainlink.hil.loop.bridge import build_plant
    from gainlink.laws import law_of

    law = law_of(art)
    scenarios = [dc.replace(sc, initial_state={"theta_dot": 1e200}) if i in blows else sc
                 for i, sc in enumerate(scenarios)]  # fmt: skip
    plants = [build_plant(sc, artifact=art) for sc in scenarios]
    runs = prepare_block(scenarios, law=law, artifact=art, plants=plants)
    for i, run in enumerate(runs):
        plan = run.plan
        if i == 2:
            noise = plan.noise.copy()
            noise[5, 0], noise[30, 1], noise[31, 0] = np.nan, np.inf, -np.inf
            plan = dc.replace(plan, noise=noise)
        if i == 4:
            R = plan.R.copy()
            R[40:] += 0.2
            plan = dc.replace(plan, R=R)
        if i == mid:
            D = plan.D.copy()
            D[60:, 0] = 1e300
            plan = dc.replace(plan, D=D)
        run.plan = plan
    if twin:
        for r in runs:  # as _twins does: the run's plant reset again
            r.plant.reset(initial=r.scenario.initial_state)
    batch = batch_of(plants)
    controller = law.reference_block(art, len(runs)) if twin else law.native_block(art, len(runs), library=library)
    return runs, batch, controller


def _both_loops(art, scenarios: list, *, twin: bool, library=None, **vary) -> tuple:
    """The C loop's and the numpy loop's records of the same block (each on its own fresh plants and laws), and
    each one's plants' and laws' states after it."""
    from gainlink.hil.loop import block as blk
    from gainlink.hil.loop import lockstep
    from gainlink.laws import law_of

    got = []
    for c in (True, False):
        runs, batch, controller = _block_inputs(art, scenarios, twin=twin, library=library, **vary)
        kw = dict(Ts=art.Ts, steps=runs[0].plan.N, disturbed=blk._disturbed(runs, twin), plant_state=not twin,
                  law_state=law_of(art).integrator_columns(art) if twin else None)  # fmt: skip
        assert lockstep.why_not(batch, controller) is None
        if c:
            rec = lockstep.run(runs, batch, controller, **kw)
        else:
            rec = blk._python_lockstep(runs, batch, controller, loop="numpy", **kw)
        laws = controller.states() if twin else _rebased(controller.host.c_block()["laws"])
        got.append((rec, batch.X.copy(), np.array(laws, copy=True)))
    return got[0], got[1]


def _rebased(words: np.ndarray) -> np.ndarray:
    """The host laws' buffer (uint64 words) with each address into itself (an instance's pointer to its own gain
    set) made an offset from its start: two buffers of the same states compare equal."""
    base, end = words.ctypes.data, words.ctypes.data + words.nbytes
    inside = (words >= base) & (words < end)
    return np.where(inside, words - np.uint64(base), words)


def _bit_for_bit(a, b) -> bool:
    """Two arrays (or two Nones) of one dtype and shape with the same bytes (NaN payloads and -0.0 included)."""
    if a is None or b is None:
        return a is None and b is None
    return (
        a.dtype == b.dtype
        and a.shape == b.shape
        and np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()
    )


@functools.cache
def _seventy_draws() -> list:
    """70 draws of the shipped campaign's first mode, 1.5 s each (planned once for both observer forms)."""
    (_, scenarios), *_ = _pendulum_campaign_points(draws=70, duration=1.5)
    return scenarios


@pytest.mark.parametrize("form", ["predictor", "current"])
def test_the_c_loop_records_what_the_numpy_loop_records_bit_for_bit(form):
    """The block's loop in one C call against the numpy loop (the oracle), on the shipped pendulum design in each
    anti-windup mode and observer form, the host C law and the twin's float64 law: 11 runs (a group of 8 lanes and
    3) with NaN/inf noise samples, a run of its own references, a plant blowing up mid-run and one in its first
    sample; 70 runs (the C's spans of 32, 32 and 6) whose last span all fails at once while the others run on, and
    whose every run fails, the last in the middle span mid-run (spans that stopped step on to the block's end); blocks
    of one run (one that runs through, one that fails at once: the loop stops). Every record (Y, U, sat, flags,
    sigma, X, L, steps, failed_at) and the plants' and laws' states after: the same bytes."""
    from gainlink.hil.campaign.worker import _library

    scenarios = _seventy_draws()
    blocks = [(scenarios[:11], {}), (scenarios, {"blows": range(64, 70)}),
              (scenarios, {"blows": set(range(70)) - {40}, "mid": 40}),
              (scenarios[:1], {"blows": ()}), (scenarios[:1], {"blows": (0,)})]  # fmt: skip
    seen = set()
    for mode in ("none", "clamp", "backcalc"):
        art = _pendulum_form(form, mode)
        library = _library(art)
        for twin in (False, True):
            for block, vary in blocks:
                (c, c_x, c_law), (py, py_x, py_law) = _both_loops(art, block, twin=twin, library=library, **vary)
                for name in STEPS_FIELDS:
                    assert _bit_for_bit(getattr(c, name), getattr(py, name)), (mode, twin, len(block), vary, name)
                assert _bit_for_bit(c_x, py_x) and _bit_for_bit(c_law, py_law), (mode, twin, len(block), vary)
                taken = int(py.steps.max())
                assert (c.lat[:taken] > 0).all() and (c.lat[taken:] == 0).all() and (np.diff(c.tick[:taken]) > 0).all()
                seen.add((twin, len(block), taken, int(py.steps.min())))
                if len(block) == 11:
                    assert py.failed_at[8] == 0 and py.failed_at[6] >= 60 and (py.failed_at[[0, 1, 2, 4]] == -1).all()
                    if not twin:
                        assert (py.flags[2, [5, 30, 31]] != 0).all() and (py.sat != 0).any()
    assert {(t, 1, 1, 1) for t in (False, True)} <= seen  # the one-run block that fails stops at once
    assert {(t, 70, 150, 1) for t in (False, True)} <= seen  # a span failed at once, the others ran on
    assert any(n == 70 and 60 < taken < 150 for _, n, taken, _ in seen)  # every run failed, the last mid-run


@pytest.mark.parametrize("mode", ["none", "backcalc"])
def test_the_twins_loop_records_the_integrators_alone_as_the_whole_states_columns(mode):
    """The twin's loop in C records of the laws' states only the integrators (all a run's trace reads of them):
    (runs, steps, q), each the integrator column of the whole state [xh, z] the numpy loop records when asked for
    every column (the shipped pendulum design, 11 runs with NaN/inf noise and plants that blow up)."""
    from gainlink.hil.loop import block as blk
    from gainlink.hil.loop import lockstep
    from gainlink.laws import law_of

    art = _pendulum_form("predictor", mode)
    columns = law_of(art).integrator_columns(art)
    assert (columns.start, columns.stop) == (art.n, art.n + art.q) and art.q == 1
    got = {}
    for c, kept in ((True, columns), (False, slice(None))):
        runs, batch, controller = _block_inputs(art, _seventy_draws()[:11], twin=True)
        kw = dict(Ts=art.Ts, steps=runs[0].plan.N, disturbed=True, plant_state=False, law_state=kept)
        run = lockstep.run if c else functools.partial(blk._python_lockstep, loop="numpy")
        got[c] = run(runs, batch, controller, **kw)
    whole = got[False].L
    assert whole.shape[2] == art.n + art.q and got[True].L.shape == (*whole.shape[:2], art.q)
    assert _bit_for_bit(got[True].L, np.ascontiguousarray(whole[:, :, art.n :]))
    assert np.isfinite(whole[0, :, art.n]).all() and np.ptp(whole[0, :, art.n]) > 0  # an integrator that moves


def test_the_block_says_where_its_loop_ran(tmp_path, monkeypatch):
    """The run's controller description names the loop: the C for the pendulum's host law and twin, numpy (and
    why) for linear plants, and numpy with the compiler's one line when the loop's C does not compile (a source
    with an error in it: what a broken compiler or header gives); the records the same whichever ran."""
    from gainlink.hil.campaign.worker import _library
    from gainlink.hil.loop import lockstep
    from gainlink.hil.loop.block import run_block

    art, scenarios = _pendulum_campaign_points(draws=2, duration=0.2)[0]
    library = _library(art)
    in_c = run_block(scenarios, artifact=art, library=library)
    assert [r.info["controller"]["loop"] for r in in_c] == [lockstep.IN_C] * 2
    linear = [dataclasses.replace(sc, plant={"kind": "linear"}) for sc in scenarios]
    block = run_block(linear, artifact=art, library=library)
    assert block[0].info["controller"]["loop"].startswith("numpy: the LinearBatch")
    broken = tmp_path / "lockstep.c"
    broken.write_text("#error this compiler cannot build the loop\n")
    monkeypatch.setattr(lockstep, "SOURCE", broken)
    lockstep._kernel.cache_clear()
    try:
        block = run_block(scenarios, artifact=art, library=library)
    finally:
        monkeypatch.undo()
        lockstep._kernel.cache_clear()
    said = block[0].info["controller"]["loop"]
    assert said.startswith("numpy: compiling the campaign block's loop (lockstep.c)") and "\n" not in said
    for got, want in zip(block, in_c):
        for name in TRACE_FIELDS:
            assert np.array_equal(getattr(got.trace, name), getattr(want.trace, name), equal_nan=True), name


@pytest.mark.parametrize("m", [1, 2, 3])
def test_the_saturation_bits_unpack_to_each_inputs_flag(m):
    """plan.saturated (a block's bits unpacked once, a run alone's per trace) against each bit read by hand, for a
    block's (runs, steps) bits, a run's (steps,) and no steps."""
    from gainlink.hil.loop.plan import saturated

    rng = np.random.default_rng(m)
    bits = rng.integers(0, 1 << m, (7, 40)).astype(np.int64)
    for b in (bits, bits[3], bits[:, :0]):
        want = np.array([[(int(x) >> j) & 1 == 1 for j in range(m)] for x in b.reshape(-1)], dtype=bool)
        got = saturated(b, m)
        assert got.dtype == bool and got.shape == (*b.shape, m)
        assert np.array_equal(got.reshape(-1, m), want.reshape(-1, m))


def test_a_block_of_more_runs_than_are_reduced_at_once_gives_each_what_it_gets_alone(monkeypatch):
    """A block of 41 of the campaign's draws, its metrics and measures reduced 16 runs at a time (RUNS_AT_ONCE made
    small: three parts), with runs without a twin, one with the model twin, one whose noise is all NaN and two whose
    plants blow up mid-run (a shorter length, in other parts): each run's trace, every metric but the timing, its
    measures and its stored trace equal what it gives alone (run_scenario, measure, downsampled_trace: the per-run
    path)."""
    from gainlink.hil.campaign.criteria import measure, measure_block
    from gainlink.hil.campaign.worker import _library, downsampled_trace, downsampled_traces
    from gainlink.hil.loop import block_metrics
    from gainlink.hil.loop.block import run_block
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import Disturbance

    monkeypatch.setattr(block_metrics, "RUNS_AT_ONCE", 16)
    count = 41
    art, scenarios = _pendulum_campaign_points(draws=count, duration=0.2)[0]
    push = (Disturbance(input="F", start=0.1, stop=0.2, value=1e300),)
    scs = []
    for i, sc in enumerate(scenarios):
        change: dict = {"twin": i % 5 != 2, "model_twin": i == 9}
        if i == 3:
            change["noise"] = dict(sc.noise) | {name: float("nan") for name in sc.noise}
        if i in (7, count - 3):
            change["disturbances"] = push
        scs.append(dataclasses.replace(sc, **change))
    library = _library(art)
    block = run_block(scs, artifact=art, library=library)
    assert block is not None and len(block) == count
    alone = [run_scenario(sc, artifact=art, library=library) for sc in scs]
    assert [i for i, r in enumerate(alone) if not r.complete] == [7, count - 3]
    assert not np.isfinite(alone[3].trace.y).all() and alone[3].trace.y.shape == alone[0].trace.y.shape
    for got, want, got_m in zip(block, alone, measure_block(block, art)):
        for name in TRACE_FIELDS + ("model_y", "model_u"):
            a, b = getattr(got.trace, name), getattr(want.trace, name)
            assert (a is None and b is None) or np.array_equal(a, b, equal_nan=True), name
        assert {k: v for k, v in got.metrics.items() if k not in TIMING_KEYS} == {
            k: v for k, v in want.metrics.items() if k not in TIMING_KEYS
        }
        assert (got.complete, got.reason) == (want.complete, want.reason)
        assert got_m == measure(want, art)
    stepped = [i for i, r in enumerate(block) if r.trace.t.size]
    for i, stored in zip(stepped, downsampled_traces([block[i].trace for i in stepped])):
        want = downsampled_trace(alone[i].trace)
        assert all(np.array_equal(stored[k], want[k], equal_nan=True) for k in "tyur")


def test_a_plant_named_relative_to_the_working_directory_is_read_from_the_current_one(
    example_artifacts, tmp_path, monkeypatch
):
    """A scenario without a file names its plant's files relative to the working directory: the one current when
    each plant is built (the block's plants ask for it once per folder, never a stale one): the pendulum's spec read
    in one folder steps as the spec's own linear model, and in a folder without it the build refuses in one line
    naming that folder."""
    import shutil

    from gainlink.errors import PlantError
    from gainlink.hil.loop.scenario import parse_scenario
    from gainlink.hil.loop.scenario_plant import build_plant
    from gainlink.hil.plants.config import plant_from_config
    from gainlink.shipping.artifact import load

    art = load(example_artifacts["pendulum"])
    spec = Path(__file__).resolve().parents[1] / "examples" / "pendulum.toml"
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir(), there.mkdir()
    shutil.copy(spec, here / "m.toml")
    table = {"artifact": str(example_artifacts["pendulum"]), "duration": 0.1,
             "plant": {"kind": "linear", "spec": "m.toml"}, "transport": {"kind": "sil"}}  # fmt: skip
    scenario = parse_scenario(table)
    monkeypatch.chdir(here)
    plant = build_plant(scenario, artifact=art)
    direct = plant_from_config({"kind": "linear", "spec": str(spec)}, artifact=art)
    plant.advance(u=np.ones(art.m), dt=art.Ts), direct.advance(u=np.ones(art.m), dt=art.Ts)
    assert np.array_equal(plant.outputs(), direct.outputs()) and np.any(plant.outputs() != 0)
    monkeypatch.chdir(there)
    with pytest.raises(PlantError) as err:
        build_plant(scenario, artifact=art)
    assert str(there / "m.toml") in str(err.value) and "\n" not in str(err.value)


def test_a_blocks_column_trees_take_what_each_runs_result_adds_or_hold_the_dicts_whole():
    """BlockMetrics.completed: the keys a run's result adds to its figures (completion, times, a plant's failure)
    become columns of the tree of runs that all have them, in each run's values; a tree whose runs differ in them
    holds its runs' dicts whole (not columnar), so the block file is made from the dicts; the rows are the dicts."""
    from gainlink.hil.loop.block_metrics import BlockMetrics

    tree = {"steps": [3, 3, 3], "twin": {"iae": [0.5, None, 1.5]}}
    trees = BlockMetrics([([0, 2, 4], tree), ([1, 3], {"steps": [0, 0]})], 5)
    finals = trees.rows()
    for i, row in enumerate(finals):
        row.update({"complete": i != 3, "wall_s": 0.25 * i})
    finals[3]["reason"] = "plant failed at step 0"  # one run of the second tree only
    done = trees.completed(finals)
    assert [positions for positions, _ in done.trees] == [[0, 2, 4], [1, 3]]
    first, second = done.trees[0][1], done.trees[1][1]
    assert first == tree | {"complete": [True, True, True], "wall_s": [0.0, 0.5, 1.0]}
    assert second == [finals[1], finals[3]] and not done.columnar
    assert done.rows() == finals
