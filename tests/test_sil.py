"""SIL: the host C loop through ctypes against the plant in-process.

Oracles: the closed loop of the artifact's own linear plant written out by hand from the law in docs/design.md
("The control law") and simulated by python-control (no saturation, so the law is linear); and the lockstep
HIL run of the same scenario over a real bus with the firmware's CAN process, which must give the same trace
bit for bit (both C loops see the same float32 samples).
"""

from __future__ import annotations

import dataclasses

import control
import numpy as np
import pytest
from gainlink.errors import ScenarioError
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.shipping.artifact import load
from support.hil import udp_transport


def _scenario(gains, **extra) -> dict:
    data = {
        "name": "sil",
        "artifact": str(gains),
        "duration": 3.0,
        "transport": {},
        "plant": {"kind": "cart_pendulum", "outputs": ["x", "theta"], "step": 0.001},
        "initial_state": {"theta": 0.05},
    }
    data.update(extra)
    return data


def _closed_loop_oracle(a, *, x0: np.ndarray, r: float, N: int) -> np.ndarray:
    """Outputs y_k of plant + law (predictor form, unsaturated) from plant state x0, estimate and integrator 0."""
    pl = a.data["plant"]
    A, B, C = (np.array(pl[k], float) for k in ("A", "B", "C"))
    P = control.c2d(control.ss(A, B, C, np.zeros((C.shape[0], B.shape[1]))), a.Ts, method="zoh")
    Ap, Bp, Cp = (np.asarray(M) for M in (P.A, P.B, P.C))
    n, q, np_ = a.n, a.q, Ap.shape[0]
    # u = -K xh - Ki z;  z+ = z + Ts (r - Ci y);  xh+ = Ad xh + Bd u + L (y - Cd xh - Dd u);  y = Cp x
    F = a.Ad - a.Bd @ a.K - a.L @ a.Cd + a.L @ a.Dd @ a.K
    G = -a.Bd @ a.Ki + a.L @ a.Dd @ a.Ki
    Acl = np.block(
        [
            [Ap, -Bp @ a.K, -Bp @ a.Ki],
            [a.L @ Cp, F, G],
            [-a.Ts * a.Ci @ Cp, np.zeros((q, n)), np.eye(q)],
        ]
    )
    Bcl = np.vstack([np.zeros((np_, q)), np.zeros((n, q)), a.Ts * np.eye(q)])
    Ccl = np.hstack([Cp, np.zeros((Cp.shape[0], n + q))])
    sys = control.ss(Acl, Bcl, Ccl, np.zeros((Cp.shape[0], q)), a.Ts)
    res = control.forced_response(
        sys, T=np.arange(N) * a.Ts, U=np.full((q, N), r), X0=np.concatenate([x0, np.zeros(n + q)])
    )
    return np.asarray(res.outputs).T


def test_sil_on_the_linear_plant_follows_the_closed_loop_of_the_law(pend):
    a = load(pend)
    sc = parse_scenario(
        _scenario(
            pend,
            plant={"kind": "linear"},
            duration=4.0,
            initial_state={"theta": 0.02},
            reference={"r_x": 0.05},
        )
    )
    res = run_scenario(sc, artifact=a)
    assert res.complete and res.metrics["mode"] == "sil" and not res.trace.sat.any()
    N = res.trace.t.size
    assert N == 400 and res.metrics["steps"] == 400 and res.metrics["lost"] == 0
    x0 = np.zeros(4)
    x0[2] = 0.02
    oracle = _closed_loop_oracle(a, x0=x0, r=0.05, N=N)
    scale = np.abs(oracle).max(axis=0)
    # The C loop computes in float32: relative 1e-4 of each output's excursion over the run.
    assert np.all(np.abs(res.trace.y - oracle).max(axis=0) <= 1e-4 * scale)
    # The float64 twin (the law around a second instance of the plant) is that same closed loop in float64,
    # and the C's run stays within float32 accuracy of it.
    assert np.all(np.abs(res.trace.twin_y - oracle).max(axis=0) <= 1e-9 * scale)
    assert res.metrics["twin"]["worst_du_rel"] <= 1e-4 and res.metrics["twin"]["worst_dy_rel"] <= 1e-4


def test_sil_equals_the_lockstep_hil_run_bit_for_bit(pend, can_firmware):
    a = load(pend)
    common = dict(
        duration=2.0,
        noise={"theta": 1e-4},
        seed=7,
        reference={"r_x": {"kind": "step", "at": 0.5, "value": 0.3}},
        disturbances=[{"input": "F", "start": 1.0, "stop": 1.05, "value": 3.0}],
    )
    sil = run_scenario(parse_scenario(_scenario(pend, **common)), artifact=a)
    hil = run_scenario(
        parse_scenario(
            _scenario(
                pend,
                transport=udp_transport(fd=True),
                mode="lockstep",
                controller="firmware",
                firmware=str(can_firmware),
                step_timeout=2.0,
                peer_timeout=4.0,
                **common,
            )
        )
    )
    assert hil.complete and hil.metrics["lost"] == 0
    assert np.array_equal(sil.trace.u, hil.trace.u)
    assert np.array_equal(sil.trace.y, hil.trace.y)
    assert np.array_equal(sil.trace.sat, hil.trace.sat)
    assert sil.metrics["tracked"] == hil.metrics["tracked"]


def test_sil_seed_sets_the_noise_and_a_failing_plant_ends_the_run(pend):
    a = load(pend)
    sc = parse_scenario(_scenario(pend, noise={"theta": 1e-3}, duration=1.0))
    r1, r2, r3 = (
        run_scenario(dataclasses.replace(sc, seed=1), artifact=a),
        run_scenario(dataclasses.replace(sc, seed=1), artifact=a),
        run_scenario(dataclasses.replace(sc, seed=2), artifact=a),
    )
    assert np.array_equal(r1.trace.y, r2.trace.y) and not np.array_equal(r1.trace.y, r3.trace.y)
    # A stiff plant for its integrator step (g = 1e6: |lambda| h ~ 14, RK4 grows ~1e3 per sub-step):
    # the state overflows, the plant refuses the step, and the run ends there.
    bad = parse_scenario(
        _scenario(
            pend,
            duration=20.0,
            initial_state={"theta": 0.1},
            plant={"kind": "cart_pendulum", "outputs": ["x", "theta"], "step": 0.01, "parameters": {"g": 1e6}},
        )
    )
    res = run_scenario(bad, artifact=a)
    assert not res.complete and "non-finite" in res.reason
    assert res.metrics["complete"] is False and res.metrics["steps"] < 2000


@pytest.mark.parametrize(
    "extra, words",
    [
        ({"faults": [{"kind": "drop", "start": 0.0, "stop": 1.0}]}, r"faults \(drop\) act on a link"),
        ({"mode": "realtime"}, "realtime"),
    ],
)
def test_sil_refuses_what_needs_a_link(pend, extra, words):
    with pytest.raises(ScenarioError, match=words):
        run_scenario(parse_scenario(_scenario(pend, **extra)), artifact=load(pend))


def test_saturation_counts_steps_with_any_input_saturated_and_each_input(example_artifacts):
    """Wood-Berry (two inputs) in SIL: a reference step and a 40 min push on the steam flow saturate both
    inputs, partly on the same steps. The report counts the steps in which any input saturated (at most the
    run's steps) and each input's own steps; the per-input counts add up to more (checked, so the case is
    the one that matters)."""
    path = example_artifacts["wood_berry"]
    a = load(path)
    sc = parse_scenario(
        {
            "name": "wb_saturation",
            "artifact": str(path),
            "duration": 150.0,
            "transport": {},
            "plant": {"kind": "linear"},
            "reference": {"r_x_D": {"kind": "step", "at": 5.0, "value": 6.0}},
            "disturbances": [{"input": "steam", "start": 20.0, "stop": 60.0, "value": 2.0}],
        }
    )
    res = run_scenario(sc, artifact=a)
    sat, N = res.trace.sat, res.trace.t.size
    per_input = [int(np.count_nonzero(sat[:, i])) for i in range(a.m)]
    any_input = int(np.count_nonzero(sat[:, 0] | sat[:, 1]))
    assert min(per_input) > 0 and any_input < sum(per_input), (per_input, any_input)
    m = res.metrics
    assert m["saturated_steps"] == any_input <= N
    assert m["saturated_steps_per_input"] == dict(zip(("reflux", "steam"), per_input))
    from gainlink.hil.loop.report import summary_text

    line = next(ln for ln in summary_text(res).splitlines() if "saturated" in ln)
    assert line.strip() == (
        f"saturated {any_input} of {N} steps (any input); per input: reflux {per_input[0]} "
        f"({100 * per_input[0] / N:.1f}%), steam {per_input[1]} ({100 * per_input[1] / N:.1f}%)"
    )


def test_the_twins_computed_after_the_run_are_the_float64_law_stepped_beside_it(pend):
    """The closed-loop twin and the model twin leave the run's per-sample path (they do not depend on it): the
    figures computed after the run must be those of the float64 law stepped sample by sample beside it, written out
    here (DESIGN.md, "How the C equals the design": a second instance of the plant, the same noise, references and
    disturbances; the model twin on the design's own Ad, Bd, Cd from the plant's initial state)."""
    from gainlink.hil.plants.config import plant_from_config
    from gainlink.proof.reference import ReferenceLoop

    a = load(pend)
    seed, sd = 5, 2e-3
    plant = {"kind": "cart_pendulum", "outputs": ["x", "theta"], "step": 0.001}
    sc = parse_scenario(_scenario(pend, plant=plant, duration=1.5, noise={"theta": sd}, seed=seed,
                                  reference={"r_x": {"kind": "step", "at": 0.3, "value": 0.2}},
                                  disturbances=[{"input": "F", "start": 0.8, "stop": 0.85, "value": 4.0}]))  # fmt: skip
    res = run_scenario(sc, artifact=a)
    N = res.trace.t.size
    t = np.arange(N) * a.Ts
    noise = np.random.default_rng(seed).standard_normal((N, 2)) * np.array([0.0, sd])
    R = np.where(t >= 0.3, 0.2, 0.0)[:, None]
    D = np.where((t >= 0.8) & (t < 0.85), 4.0, 0.0)[:, None]
    second = plant_from_config(plant, artifact=a)
    second.reset(initial={"theta": 0.05})
    Ad, Bd, Cd, Dd = a.design_plant()
    x = np.array([0.0, 0.0, 0.05, 0.0])  # the plant's initial state by name, about the origin (x_op none)
    twin, model = ReferenceLoop(a), ReferenceLoop(a)
    Ty, Tu, My, Mu = np.zeros((N, 2)), np.zeros((N, 1)), np.zeros((N, 2)), np.zeros((N, 1))
    du_prev = np.zeros(1)
    for k in range(N):
        Ty[k] = second.outputs() + noise[k]
        Tu[k] = twin.step(Ty[k], R[k]).u
        second.advance(u=Tu[k] + D[k], dt=a.Ts)
        My[k] = Cd @ x + Dd @ du_prev + noise[k]
        Mu[k] = model.step(My[k], R[k]).u
        du_prev = Mu[k]
        x = Ad @ x + Bd @ (Mu[k] + D[k])
    tr = res.trace
    assert np.array_equal(tr.twin_y, Ty) and np.array_equal(tr.twin_u, Tu)
    assert np.array_equal(tr.model_y, My) and np.array_equal(tr.model_u, Mu)
    assert res.metrics["model_twin"]["start"] == "the plant's initial state"
