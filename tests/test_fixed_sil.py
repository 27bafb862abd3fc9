"""Software in the loop (and so campaigns, whose runs are SIL) of a fixed-point artifact runs the integer law it
certifies, not the float32 law of the same export (it did: NativeLoop on the float library). The oracle is the
bit-exact integer model (gainlink.laws.fixed.model) on the float32 samples the run recorded."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gainlink.hil.campaign.runner import run as run_campaign
from gainlink.hil.campaign.store import Store
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.native import FixedNativeLoop
from gainlink.laws.fixed.qformat import real
from gainlink.laws.lq.model import Float32Loop
from support.fixed import example, model_run

pytestmark = pytest.mark.xdist_group("test_fixed_sil")  # one worker builds the q31 library once


@pytest.fixture(scope="module")
def pend_q31(tmp_path_factory):
    a = example("pendulum", "q31")
    path = tmp_path_factory.mktemp("q31") / "gains.json"
    a.save(path)
    return a, path


def _scenario(path, **extra) -> dict:
    return {
        "name": "q31_sil",
        "artifact": str(path),
        "duration": 2.0,
        "transport": {},  # software in the loop: no link
        "controller": "firmware",
        "seed": 3,
        "plant": {"kind": "cart_pendulum", "outputs": ["x", "theta"], "step": 0.005},
        "initial_state": {"theta": 0.05},
        "reference": {"r_x": {"kind": "step", "at": 0.5, "value": 0.2}},
        "noise": {"theta": 1e-4},
        **extra,
    }


def test_sil_of_a_q31_artifact_is_the_integer_law_bit_for_bit(pend_q31):
    a, path = pend_q31
    res = run_scenario(parse_scenario(_scenario(path)), artifact=a)
    tr = res.trace
    assert res.complete and tr.t.size == 200
    assert "q31 fixed-point" in res.info["controller"]["kind"]
    Y, R = tr.y.astype(np.float32), tr.r.astype(np.float32)
    model = model_run(a, Y, R)
    u_model = real(model.U, FixedPointLoop(a).f["u"]).astype(np.float32)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), u_model.view(np.uint32))
    np.testing.assert_array_equal(np.sum(tr.sat.astype(np.int64) << np.arange(a.m), axis=1), model.sat)
    f32 = Float32Loop(a).run(Y.astype(np.float64), R.astype(np.float64))
    assert np.any(f32.u.astype(np.float32) != tr.u.astype(np.float32))  # not the float law of the same export
    fx = res.metrics["fixed_point"]
    assert fx["law"] == "q31" and fx["bit_exact"] is True and fx["within_per_step"]
    assert 0 < fx["measured_du_per_step"][0] <= a.checks["fixed_point"]["error"]["per_step_rounding"][0]


def test_a_non_finite_sample_is_refused_with_the_float_loops_status_and_the_models_command(pend_q31):
    """A NaN sample: the integer law's fault flag becomes the float loop's refused-sample status (GL_ERR_NANINF)
    and the command is the model's for that sample."""
    a, _ = pend_q31
    Y = np.array([[0.01, 0.02], [np.nan, 0.0], [0.01, 0.0]], dtype=np.float32)
    R = np.zeros((3, 1), dtype=np.float32)
    law = FixedNativeLoop(a)
    outs = [law.step(Y[k], R[k]) for k in range(3)]
    model = model_run(a, Y, R)
    assert [o.status for o in outs][1] == -2 and list(model.fault) == [False, True, False]
    u_model = real(model.U, FixedPointLoop(a).f["u"]).astype(np.float32)
    np.testing.assert_array_equal(np.array([o.u for o in outs], dtype=np.float32), u_model)


def test_a_campaign_of_a_q31_artifact_runs_the_integer_law_on_its_workers(pend_q31, tmp_path):
    _, path = pend_q31
    data = {
        "name": "q31",
        "kind": "sil",
        "seed": 2,
        "runs": 2,
        "artifact": str(path),
        "scenario": {k: v for k, v in _scenario(path).items() if k not in ("name", "artifact", "seed", "transport")},
        "criteria": {"bounds": {"theta": [-0.5, 0.5]}},
    }
    out = tmp_path / "out"
    result = run_campaign(data, out=out, workers=1, plots=False)
    doc = json.loads((out / "campaign.json").read_text())
    assert doc["counts"]["runs"] == 2 and doc["counts"]["error"] == 0, result
    records = [rec for _, rec in Store(out).records()]
    assert len(records) == 2
    for rec in records:
        assert rec["metrics"]["fixed_point"]["bit_exact"] is True and rec["metrics"]["fixed_point"]["law"] == "q31"
