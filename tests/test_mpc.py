"""The MPC law (issue 32; docs/design.md, "MPC (the fourth law)"): its references, each its own claim, and its C.

Oracles: python-control's DLQR gain of the same weights (the LQ law the unconstrained optimum's first move must be),
Clarabel's interior-point solution of the QP written out independently of the solver (gainlink.laws.mpc.qp builds it
from the artifact's matrices, not from the ADMM's cached gains), the float32 model of the C (gainlink.laws.mpc with
the C's arithmetic) against the host build and the Cortex-M images, run from the same samples.
"""

from __future__ import annotations

import tomllib

import control
import numpy as np
import pytest
from gainlink.laws import flags as law_flags
from gainlink.laws import law_for_spec, law_of
from gainlink.laws.mpc import qp
from gainlink.laws.mpc.arith import Arith, Float32
from gainlink.laws.mpc.solver import Tables, Workspace, solve
from gainlink.laws.mpc.step import MpcLoop
from gainlink.shipping.artifact import from_dict
from gainlink.spec import parse_spec
from support.cli import assert_refused
from support.designs import designed
from support.mpc import mpc_pendulum as pendulum
from support.paths import EXAMPLES


def artifact(**kw):
    return from_dict(designed(pendulum(**kw)))


def admm(a, x0: np.ndarray, *, cap: int = 5000):
    """The float64 algorithm from a cold start, run to its tolerances (a cap far away)."""
    t = Tables.of(a.mpc, Arith())
    t.max_iter = cap
    return solve(t, Arith(), Workspace.zeros(a.mpc.horizon, a.m, a.mpc.nc), x0)


def test_the_unconstrained_optimum_first_move_is_the_lq_law_within_float64_rounding():
    a = artifact()
    m = a.mpc
    Kd, _, _ = control.dlqr(m.A, m.B, m.Q, m.R)  # python-control's own DLQR of the design's weights
    rng = np.random.default_rng(5)
    for _ in range(5):
        x0 = rng.normal(0.0, 0.02, m.nx)  # small: the first moves stay far inside the 20 N box
        want = -np.asarray(Kd) @ x0
        kkt = qp.unconstrained(m, x0)
        clarabel = qp.solve_qp(m, x0)
        assert np.all(np.abs(clarabel.u) < 0.5 * (a.u_max - a.u_min)), "a constraint is active: not this claim"
        assert np.allclose(kkt.u[0], want, rtol=1e-9, atol=1e-12), (kkt.u[0], want)
        assert np.allclose(clarabel.u[0], want, rtol=1e-7, atol=1e-9), (clarabel.u[0], want)


@pytest.mark.parametrize(
    "case",
    [
        {"box": None, "soft": None, "x0": [1.0, 0.0, 0.0, 0.0, 0.0]},  # unconstrained: a proximal iteration
        {"box": 2.5, "soft": None, "x0": [1.0, 0.0, 0.0, 0.0, 0.0]},  # the input box binds for the whole horizon
        {"box": 2.5, "soft": {"x_dot": [-0.3, 0.3]}, "x0": [0.3, 0.2, 0.05, 0.0, 0.1]},  # and a soft velocity box
    ],
)
def test_the_float64_algorithm_stops_within_its_tolerance_of_clarabels_optimum(case):
    a = artifact(box=case["box"], soft=case["soft"])
    x0 = np.array(case["x0"])
    opt = qp.solve_qp(a.mpc, x0)
    run = admm(a, x0)
    assert run.converged
    gap = np.abs(run.u[0] - opt.u[0])
    assert np.all(gap <= a.mpc.eps["pu"]), (gap, a.mpc.eps["pu"], run.iterations)


def test_at_the_cap_the_first_move_is_projected_and_flagged_and_the_count_is_the_caps():
    a = artifact(horizon=4, box=2.5, cap=2)
    model = law_of(a).model(a)
    step = model.step(np.array([1.0, 0.0]), np.zeros(1), np.zeros(0))
    step = model.step(np.array([1.0, 0.0]), np.zeros(1), np.zeros(0))  # the estimate has moved: the box binds
    assert step.flags & law_flags.CAPPED
    assert model.last.iterations == 2
    assert a.u_min[0] <= step.u[0] <= a.u_max[0] and step.sat == 1


def _samples(a, k: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    Y = a.y_op + np.array([1.0, 0.0]) + rng.normal(0.0, 0.01, (k, a.p))
    Y[k // 2, 1] = np.nan  # refused: FAULT, nothing changes
    return Y, np.zeros((k, a.q))


@pytest.mark.parametrize("soft", [None, {"x_dot": [-0.3, 0.3], "theta": [-0.2, 0.2]}])
def test_the_host_c_is_its_float32_model_bit_for_bit_and_near_the_float64_algorithm(soft):
    a = artifact(horizon=5, box=2.5, soft=soft, cap=4)
    law = law_of(a)
    Y, R = _samples(a, 24)
    native, model = law.replay(a, "native", Y, R), law.replay(a, "model", Y, R)
    for field in ("u", "sat", "flags", "iterations", "state"):
        assert np.array_equal(getattr(native, field), getattr(model, field)), field
    assert native.flags[12] == law_flags.FAULT and native.iterations[12] == 0
    assert np.array_equal(native.state[12], native.state[11])  # a refused sample changes nothing
    assert (native.flags & law_flags.CAPPED).any() and (native.iterations < a.mpc.max_iter).any()
    verdicts = law.one_step(a, Y, R, None, native, engine="native")
    assert [v.passed for v in verdicts] == [True, True], [v.check.summary() for v in verdicts]


def test_a_bent_gain_is_caught_by_the_one_step_check():
    a = artifact(horizon=5, box=2.5)
    law = law_of(a)
    Y, R = _samples(a, 10)
    bent = MpcLoop(a, Float32())
    bent.law.t.negK[2, 0, 1] = np.float32(bent.law.t.negK[2, 0, 1] * (1 + 1e-4))  # one cached gain of stage 2
    trace = bent.run(Y, R)
    assert law.one_step(a, Y, R, None, law.replay(a, "model", Y, R), engine="model")[0].passed
    verdicts = law.one_step(a, Y, R, None, trace, engine="model")
    assert not verdicts[0].passed and verdicts[0].check.first_failure.k == 1  # step 0 starts cold: u0 = 0


@pytest.mark.parametrize(
    "target,steps",
    [("cortex-m4", 12), ("cortex-m0", 3)]
    + [pytest.param(t, 12, marks=pytest.mark.matrix) for t in ("cortex-m3", "cortex-m7", "cortex-m33", "cortex-m55")],
)
def test_the_cortex_m_image_is_the_host_c_bit_for_bit(target, steps):
    """Host C and the image in QEMU, bit for bit, on every core (the M4F and the M0 in ``make test``, the other four
    under ``-m matrix``): commands, saturation, flags, iteration counts and the solver's whole state."""
    a = artifact(horizon=4, box=2.5, soft={"x_dot": [-0.3, 0.3]})
    law = law_of(a)
    Y, R = _samples(a, steps, seed=2)
    Y[1, 0] = np.nan
    host, image = law.replay(a, "native", Y, R), law.replay(a, "qemu", Y, R, target=target)
    for field in ("u", "sat", "flags", "iterations", "state"):
        assert np.array_equal(getattr(host, field), getattr(image, field)), field


BAD = [
    ({"mpc": {"horizon": 0}}, "mpc.horizon must be an integer from 1"),
    ({"mpc": {"horizon": 5, "max_iter": 0}}, "mpc.max_iter must be an integer from 1"),
    ({"mpc": {"horizon": 5, "rho": 0.0}}, "mpc.rho must be a finite number > 0"),
    ({"mpc": {"horizon": 5, "rho_state": -1.0}}, "mpc.rho_state must be a finite number > 0"),
    ({"mpc": {"horizon": 5, "boxes": {"x_dot": [0.5, 1.0]}}}, "excludes the operating point"),
    ({"implementation": {"numeric": "q31"}}, "not available for the MPC law"),
    ({"mpc": None}, 'method = "mpc" needs an [mpc] table'),
]


def _toml(data: dict) -> str:
    lines = []
    for key in ("name", "Ts", "discretization"):
        lines.append(f"{key} = {data[key]!r}".replace("'", '"'))
    for table, body in data.items():
        if not isinstance(body, dict):
            continue
        lines.append(f"[{table}]")
        for k, v in body.items():
            if isinstance(v, dict):
                v = "{ " + ", ".join(f"{kk} = {vv}" for kk, vv in v.items()) + " }"
            elif isinstance(v, str):
                v = f'"{v}"'
            lines.append(f"{k} = {v}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("change,phrase", BAD, ids=[p for _, p in BAD])
def test_bad_mpc_input_is_one_line_exit_2_and_nothing_written(tmp_path, change, phrase):
    data = pendulum()
    for table, body in change.items():
        if body is None:
            data.pop(table)
        else:
            data.setdefault(table, {}).update(body)
    spec = tmp_path / "spec.toml"
    spec.write_text(_toml(data))
    assert_refused(["design", spec, "--out", tmp_path / "out.json"], phrase, tmp_path)


def test_a_terminal_cost_that_is_not_positive_definite_is_refused(tmp_path):
    data = pendulum()
    data["plant"].update(A=[[-1.0, 0.0, 0.0, 0.0], [0.0, -2.0, 0.0, 0.0], [0.0, 0.0, -3.0, 0.0],
                            [0.0, 0.0, 0.0, -4.0]])  # fmt: skip
    data["controller"]["Q_diag"] = [1.0, 0.0, 1.0, 1.0]  # a stable mode the cost does not see: P singular
    data.pop("integral")
    data["limits"]["anti_windup"] = "none"
    spec = tmp_path / "spec.toml"
    spec.write_text(_toml(data))
    assert_refused(["design", spec, "--out", tmp_path / "out.json"], "terminal cost", tmp_path)


def test_an_mpc_law_with_a_schedule_is_refused_in_one_line():
    data = pendulum()
    data["schedule"] = {"sigma": "x", "points": [0.0, 1.0]}
    with pytest.raises(ValueError, match="cannot be scheduled"):
        law_for_spec(parse_spec(data))


# The M0's run is the matrix's: its image is the host C bit for bit, whole state included, in make test
# (test_the_cortex_m_image_is_the_host_c_bit_for_bit[cortex-m0-3]), and PIL's loop is the M4F's run's
@pytest.mark.slow(cpu=5)
@pytest.mark.parametrize("target,steps", [("cortex-m4", 40), pytest.param("cortex-m0", 4, marks=pytest.mark.matrix)])
def test_pil_closes_the_loop_on_the_image_and_its_records_are_the_float32_model_step_by_step(target, steps):
    """PIL on the M4F and (``-m matrix``) a very short run on the M0 (~3M instructions a step through gl_fmaf): the
    image's records (command, flags, iterations, its whole state) are checked from its own state against the float32
    model, and its commands are the model's fed the float32 samples the plant gave, in turn."""
    from gainlink.hil.loop.pil import make_plant, run_pil

    a = artifact(horizon=5, box=2.5)
    plant = make_plant("artifact", artifact=a, x0=np.array([1.0, 0.0, 0.0, 0.0]))  # 1 m off: the box binds
    res = run_pil(a, plant=plant, steps=steps, target=target, model_twin=False)
    block = res.summary()["mpc"]
    assert res.law == "mpc-float32" and block["bit_exact"] and block["solved_steps"] == steps
    model = law_of(a).model(a)
    want = [model.step(res.y[k].astype(np.float32).astype(float), np.zeros(1), np.zeros(0)) for k in range(steps)]
    np.testing.assert_array_equal(res.u.view(np.uint32), np.array([w.u for w in want], np.float32).view(np.uint32))
    np.testing.assert_array_equal(res.flags, [w.flags for w in want])
    capped = sum(bool(w.flags & law_flags.CAPPED) for w in want)
    assert block["capped_steps"] == capped and (capped > 0 or steps < 10)  # the longer run meets the cap


def test_a_sil_run_reports_the_solvers_iterations_as_the_c_ran_them():
    """The run report's mpc block (counted by the float32 model on the samples the controller received) against the
    host C's own records: the CAPPED flags the trace carries and the iterations the C replays to on those samples."""
    from gainlink.hil import run as hil_run

    a = artifact(horizon=5, box=2.5)
    steps = 40
    scenario = {"name": "mpc_sil", "artifact": "unused.json", "duration": steps * a.Ts, "controller": "firmware",
                "plant": {"kind": "linear"}, "initial_state": {"x": 1.0}, "transport": {}, "twin": False,
                "model_twin": False}  # fmt: skip
    res = hil_run(scenario, artifact=a)
    assert res.complete
    tr, block = res.trace, res.metrics["mpc"]
    c = law_of(a).replay(a, "native", tr.y.astype(np.float32), tr.r.astype(np.float32))
    capped = np.count_nonzero(tr.flags & law_flags.CAPPED)  # a step may also converge at its cap-th iteration
    assert block["capped_steps"] == capped > 0 and capped <= np.count_nonzero(c.iterations == a.mpc.max_iter)
    assert block["iterations_max"] == c.iterations.max() and block["iterations_mean"] == pytest.approx(
        c.iterations.mean()
    )
    assert "stopped at the cap" in "\n".join(law_of(a).report_lines(res.metrics))


@pytest.mark.parametrize("fd", [False, True])
def test_over_can_the_answers_say_capped_and_the_report_reads_it_from_the_wire(fd):
    """HIL over classic CAN (8-byte frames) and CAN FD (udp_multicast) to the firmware's host CAN node on the MPC law,
    from 1 m off: the commands carry CAPPED (wire format 4: classic, byte 3's high nibble; FD, byte 3, the flags'
    bits 8-15), the trace records it from the frames, and the report's count read from the wire is the host C's on
    the same samples, step by step."""
    from gainlink.hil import run as hil_run
    from support.hil import udp_transport

    a = artifact(horizon=5, box=2.5)
    steps = 30
    scenario = {"name": "mpc_can", "artifact": "unused.json", "duration": steps * a.Ts, "controller": "firmware",
                "plant": {"kind": "linear"}, "initial_state": {"x": 1.0}, "transport": udp_transport(fd=fd),
                "twin": False, "model_twin": False}  # fmt: skip
    res = hil_run(scenario, artifact=a)
    assert res.complete and res.trace.got.all() and res.info["transport"]["kind"] == "can"
    tr, block = res.trace, res.metrics["mpc"]
    c = law_of(a).replay(a, "native", tr.y.astype(np.float32), tr.r.astype(np.float32))
    wire = tr.flags & law_flags.CAPPED
    assert np.array_equal(wire, c.flags & law_flags.CAPPED) and np.count_nonzero(wire) > 0
    assert block["capped_steps_read"] == block["capped_steps"] == np.count_nonzero(wire)
    assert block["capped_read_is_the_models"]
    assert "said CAPPED on the link, as the model's" in "\n".join(law_of(a).report_lines(res.metrics))


def test_the_mpc_campaign_and_its_lqi_counterpart_draw_the_same_plants_and_an_mpc_run_reports_its_solver():
    """examples/campaigns/pendulum_mpc_mass_uncertainty.toml against the LQI law of pendulum.toml (bench/mpc_pays.py
    pairs them on the draw): the same seed draws the same plant parameters for both laws, each campaign designs its
    own law, and a run of the MPC campaign (the worker's function) reports the iterations of the C that ran."""
    import json

    from gainlink.hil.campaign.config import parse_campaign
    from gainlink.hil.campaign.plan import plan_campaign
    from gainlink.hil.campaign.worker import execute
    from support.paths import EXAMPLES

    path = EXAMPLES / "campaigns" / "pendulum_mpc_mass_uncertainty.toml"
    plans = {}
    for law, spec in (("mpc", "../pendulum_mpc.toml"), ("lq", "../pendulum.toml")):
        data = tomllib.loads(path.read_text()) | {"spec": spec, "runs": 2}
        data["scenario"] |= {"twin": False, "duration": 0.5}
        plans[law] = plan_campaign(parse_campaign(data, path=path))
    mpc, lq = plans["mpc"].runs, plans["lq"].runs
    assert len(mpc) == len(lq) == 4  # two boxes x two draws
    for a, b in zip(mpc, lq, strict=True):
        assert a.values == b.values and a.scenario["plant"] == b.scenario["plant"] and a.seed == b.seed
    names = {law: {law_of(from_dict(json.loads(art))).name for art in plans[law].artifacts.values()} for law in plans}
    assert names == {"mpc": {"mpc/float32"}, "lq": {"lq/float32"}}
    p = mpc[0]
    rec = execute("sil", plans["mpc"].artifacts[p.artifact_sha256], p.scenario, p.seed, plans["mpc"].blobs)
    block = rec["metrics"]["mpc"]
    assert rec["status"] == "done" and block["solved_steps"] == rec["metrics"]["steps"] == 50
    assert 1 <= block["iterations_mean"] <= block["iterations_max"] <= block["cap"] == 10


def test_a_non_finite_sample_gets_the_safe_command_and_leaves_the_c_solvers_state_untouched():
    """The host C: a NaN sample between two steps answers u_op clamped into the box with the fault flag, and its
    record's state (estimate, integrators, warm start) is the step before's, so the next step is the step it would
    have been without the NaN."""
    from gainlink.firmware.host import HostLaw

    a = artifact(horizon=5, box=2.5)
    y, r = np.array([0.3, 0.02]), np.zeros(1)
    host = HostLaw(a)
    host.step(y, r)
    before = host.step(y, r)
    bad = host.step(np.array([np.nan, 0.0]), r)
    after = host.step(y, r)
    assert int(bad["flags"]) & law_flags.FAULT and bad["u"][0] == np.float32(np.clip(a.u_op[0], -2.5, 2.5))
    assert np.array_equal(bad["state"], before["state"])
    clean = HostLaw(a)
    for _ in range(3):
        want = clean.step(y, r)
    assert np.array_equal(after["u"], want["u"]) and np.array_equal(after["state"], want["state"])


def test_an_image_whose_mpc_workspace_does_not_fit_the_boards_ram_is_refused_with_the_linkers_figure():
    """The quadrotor's MPC (12 states, 4 inputs, N = 10) on the micro:bit's 16 KiB of RAM: the build fails in one
    line that says by how much the RAM overflows (not the linker's exit status)."""
    from gainlink.errors import ToolchainError
    from gainlink.firmware.build import replay_image
    from gainlink.laws import design
    from gainlink.spec import load_spec

    a = from_dict(design(load_spec(EXAMPLES / "quadrotor_hover_mpc.toml")).artifact)
    with pytest.raises(ToolchainError, match=r"region .RAM. overflowed by \d+ bytes"):
        replay_image(a, target="cortex-m0", board="microbit")


@pytest.mark.slow(cpu=6)
def test_pil_counts_the_mpc_steps_instructions_within_the_cost_benchmarks_bound_at_the_cap():
    """`pil run` on the M4F counts ``gl_mpc_step`` (callees included) on examples/pendulum_mpc.toml from 1 m off, where
    the cap stops the solver: its worst step is within bench/mpc_cost.py's bound at the cap (the fixed part plus the
    cap times the dearest iteration, recorded in bench/results/mpc_cost.json from replayed samples) and the issue's
    target of 50,000, and its capped steps cost more than a step that stops early. The run's own bound (the law's, on
    the image PIL ran) is proved, covers the run's worst, is fixed + cap x per iteration as the summary prints it, and
    is the bench's recorded bound for the M4F image."""
    import json
    import re
    import tomllib

    from gainlink.hil.loop.pil import make_plant, run_pil
    from gainlink.hil.loop.pil_report import instruction_lines
    from gainlink.laws import design
    from gainlink.spec import load_spec
    from support.paths import ROOT

    a = from_dict(design(load_spec(EXAMPLES / "pendulum_mpc.toml")).artifact)
    rec = json.loads((ROOT / "bench" / "results" / "mpc_cost.json").read_text())
    (row,) = [d for d in rec["designs"] if d["design"] == "pendulum_mpc"]
    (m4,) = [t for t in row["targets"] if t["target"] == "cortex-m4"]
    plant = make_plant("artifact", artifact=a, x0=np.array([1.0, 0.0, 0.0, 0.0]))
    res = run_pil(a, plant=plant, steps=30, target="cortex-m4", model_twin=False)
    block, mpc = res.summary()["instructions_per_step"], res.summary()["mpc"]
    assert block["symbol"] == "gl_mpc_step" and block["calls"] == 30 and mpc["capped_steps"] > 0
    assert block["fewest"] < block["mean"] <= block["worst"] <= m4["bound_per_step_at_cap"] <= 50_000
    # the law's own bound on this image (Law.cost_bound), printed beside the counts and written in pil.json: at least
    # the run's worst, fixed + cap x per iteration as printed, and the bench's bound for the same image measured apart
    bound = block["bound"]
    assert bound["proved"] and bound["core"] == "cortex-m4" and block["worst"] <= bound["per_step"]
    (line,) = [ln for ln in instruction_lines(block) if "bound at the cap" in ln]
    got = re.search(r"proved on cortex-m4: (\d+) instructions per step = fixed (\d+) \+ cap (\d+) x (\d+) per", line)
    per_step, fixed, cap, per_iteration = map(int, got.groups())
    assert cap == tomllib.loads((EXAMPLES / "pendulum_mpc.toml").read_text())["mpc"]["max_iter"]
    assert per_step == fixed + cap * per_iteration == bound["per_step"]
    assert (per_step, per_iteration) == (m4["bound_per_step_at_cap"], m4["proof"]["per_iteration"])
    assert "instructions, not cycles" in instruction_lines(block)[0]
