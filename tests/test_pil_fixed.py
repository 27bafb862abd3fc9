"""Processor-in-the-loop of a fixed-point artifact: the integer image (firmware/ports/cortex-m/main.c) on the
Cortex-M0 (micro:bit) and M3 (MPS2-AN385) closes the loop with the pendulum's model through the float image's
stream. The oracles, recomputed here: the bit-exact integer model (gainlink.laws.fixed.model, through
tests/support/fixed.py) fed the very float32 samples the image received writes the image's words step for step;
the float64 law with the quantised coefficients, closing the loop on a fresh plant, stays within the certified
closed-loop bound widened by the link's float32 roundings (gainlink.laws.fixed.link)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.laws.fixed.firmware import FAULT, FixedRun, run_host
from gainlink.laws.fixed.link import bound_float32_link
from gainlink.laws.fixed.model import gains_from_artifact
from gainlink.laws.fixed.pil import model_records
from gainlink.laws.image import first_difference
from gainlink.proof.derived_law import DerivedLoop
from gainlink.shipping.artifact import from_dict, seal
from support.cli import run_cli
from support.fixed import example, model_run

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")

STEPS = 300
REFERENCE = [0.5]


def _quantised_loop(a, steps: int, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The float64 law with the artifact's quantised coefficients around a fresh model: commands, and per step
    whether it saturated."""
    plant, law = make_plant("artifact", artifact=a, x0=x0), DerivedLoop(gains_from_artifact(a).ideal)
    U, S = np.zeros((steps, a.m)), np.zeros(steps, dtype=bool)
    for k in range(steps):
        res = law.step(plant.outputs(), REFERENCE)
        U[k], S[k] = res.u, res.saturated.any()
        plant.advance(u=res.u)
    return U, S


@pytest.mark.parametrize("target", ["cortex-m0", "cortex-m3"])
def test_pendulum_q31_pil_equals_the_model_and_stays_within_the_bound(target):
    a = example("pendulum", "q31")
    x0 = np.full(a.n, 0.05)
    plants = [make_plant("artifact", artifact=a, x0=x0) for _ in range(3)]
    res = run_pil(
        a, plant=plants[0], steps=STEPS, reference=REFERENCE, target=target, twin=plants[1], check_plant=plants[2]
    )
    assert not np.any(res.flags & 0x01)  # no sample refused (the fault flag)
    # bit for bit: the model fed the samples the image received (float32), from the initial state
    model = model_run(a, res.y.astype(np.float32), np.broadcast_to(np.float32(REFERENCE), (STEPS, a.q)))
    run = FixedRun.from_records(res.records, a.q)
    for field in ("U", "V", "XH", "Z", "sat", "clip"):
        assert np.array_equal(getattr(run, field), getattr(model, field)), field
    assert not np.any(run.flags) and not np.any(run.overflow)
    fu = a.checks["fixed_point"]["formats"]["u"]
    assert np.array_equal(res.u, np.ldexp(run.U.astype(float), -np.array(fu)).astype(np.float32))
    # within the bound of the quantised float64 twin: recomputed on a fresh plant
    U, saturated = _quantised_loop(a, STEPS, x0)
    assert not saturated.any() and not run.sat.any(), "the scenario stays unsaturated (the certificate's case)"
    measured = np.abs(res.u - U).max(axis=0)
    bound = bound_float32_link(a)
    assert np.all(measured <= bound), (measured, bound)
    assert np.all(measured > 0), "the integer law is not the float64 one: something to measure"
    check = res.checks["fixed_point"]
    assert check.bit_exact and check.first_difference is None and check.within_bound
    assert check.unsaturated_steps == STEPS and np.array_equal(check.measured_du_rounding, measured)
    assert check.certified_du_rounding == a.checks["fixed_point"]["error"]["closed_loop"]
    assert check.bound_du_float32_link == list(bound)


def test_pil_cli_on_a_fixed_point_artifact_reports_the_oracle(tmp_path):
    a = example("pendulum", "q31")
    gains = tmp_path / "gains.json"
    a.save(gains)
    out = tmp_path / "pil"
    res = run_cli(
        "pil", "run", gains, "--board", "microbit", "--steps", "200", "--reference", "0.2", "--out", out, "--json"
    )
    assert res.code == 0, res.err
    summary = json.loads(res.out)
    assert summary["target"] == "cortex-m0" and summary["steps"] == 200 and summary["faults"] == 0
    fp = summary["fixed_point"]
    assert fp["numeric"] == "q31" and fp["bit_exact"] and fp["within_bound"] and fp["certificate_applies"]
    assert fp["measured_du_rounding"][0] <= fp["bound_du_float32_link"][0]
    assert fp["certified_du_design"] == a.checks["fixed_point"]["error"]["certified"]
    assert json.loads((out / "pil.json").read_text()) == summary


def test_the_check_plant_closes_a_loop_only_for_a_law_whose_check_needs_one():
    """The same design in float32 (its fixed-point check removed): no quantised twin, no integer check."""
    data = copy.deepcopy(example("pendulum", "q31").data)
    del data["checks"]["fixed_point"]
    a = from_dict(seal(data))
    res = run_pil(a, plant=make_plant("artifact", artifact=a), steps=5, check_plant=make_plant("artifact", artifact=a))
    assert res.law == "float32" and res.checks == {} and "fixed_point" not in res.summary()


@pytest.mark.parametrize("name,numeric", [("pendulum", "q31"), ("wood_berry", "q15")])
def test_the_oracle_writes_the_records_the_host_c_writes(name, numeric):
    """PIL's bit-for-bit oracle (model_records) against the host build, with samples past their ranges and a NaN:
    equal in every field, and first_difference finds a flipped bit where it is."""
    a = example(name, numeric)
    rng = np.random.default_rng(3)
    ranges = a.checks["fixed_point"]["ranges"]
    lo, hi = np.array(ranges["y_min"]), np.array(ranges["y_max"])
    Y = (lo + (hi - lo) * rng.uniform(-0.2, 1.2, (120, a.p))).astype(np.float32)
    rlo, rhi = np.array(ranges["r_min"]), np.array(ranges["r_max"])
    R = (rlo + (rhi - rlo) * rng.uniform(-0.2, 1.2, (120, a.q))).astype(np.float32)
    Y[50, 0] = np.nan
    model = model_records(a, Y, R)
    host = run_host(a, Y, R)
    mine = FixedRun.from_records(model, a.q)
    for field in ("U", "V", "XH", "Z", "flags", "sat", "clip", "overflow"):
        assert np.array_equal(getattr(mine, field), getattr(host, field)), field
    assert np.array_equal(mine.u.view(np.uint32), host.u.view(np.uint32))
    assert np.any(host.clip) and host.flags[50] & FAULT
    assert first_difference(model, model.copy()) is None
    flipped = model.copy()
    flipped["XH"][77, 0] ^= 1
    assert first_difference(flipped, model) == {"step": 77, "field": "XH"}
