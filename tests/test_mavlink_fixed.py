"""The MAVLink host app runs a fixed-point artifact's own law: the integer law it certifies (not the float law of the
same export), checked in lockstep HIL over MAVLink against the bit-exact integer model (gainlink.proof.fixed_law) on
the samples the run recorded."""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.proof.fixed_format import real
from gainlink.proof.fixed_law import FixedPointLoop
from gainlink.proof.float32_law import Float32Loop
from support.fixed import example, model_run
from support.net import udp_port


@pytest.fixture(scope="module")
def pend_q31(tmp_path_factory):
    """The pendulum designed in q31, saved."""
    a = example("pendulum", "q31")
    path = tmp_path_factory.mktemp("mavq31") / "gains.json"
    a.save(path)
    return a, path


def _scenario(path, **extra):
    data = {
        "name": "pendulum_q31_mavlink",
        "artifact": str(path),
        "duration": 2.0,
        "mode": "lockstep",
        "controller": "firmware",
        "step_timeout": 2.0,
        "seed": 5,
        "plant": {"kind": "fmu", "fmu": "cart_pendulum", "outputs": ["x", "theta"]},
        "transport": {"kind": "mavlink", "port": udp_port()},
        "initial_state": {"theta": 0.1},
        "reference": {"r_x": {"kind": "step", "at": 0.5, "value": 0.2}},
        "noise": {"theta": 1e-4},
        **extra,
    }
    return parse_scenario(data, path=path.parent / "scenario.toml")


def test_q31_over_mavlink_is_the_integer_law_bit_for_bit_on_the_recorded_samples(pend_q31):
    a, path = pend_q31
    res = run_scenario(_scenario(path))
    tr = res.trace
    assert res.complete and res.metrics["lost"] == 0 and tr.t.size == 200, res.reason
    assert "law=q31" in res.info["controller"]["ready"]
    Y, R = tr.y.astype(np.float32), tr.r.astype(np.float32)
    model = model_run(a, Y, R)
    u_model = real(model.U, FixedPointLoop(a).f["u"]).astype(np.float32)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), u_model.view(np.uint32))
    sat = np.sum(tr.sat.astype(np.int64) << np.arange(a.m), axis=1)
    np.testing.assert_array_equal(sat, model.sat)
    assert not model.fault.any() and not tr.status.any()
    # not the float32 law of the same export (what the MAVLink app ran before it chose the law)
    f32 = Float32Loop(a).run(Y.astype(np.float64), R.astype(np.float64))
    assert np.any(f32.u.astype(np.float32) != tr.u.astype(np.float32))
    fx = res.metrics["fixed_point"]
    assert fx["law"] == "q31" and fx["bit_exact"] is True and fx["within_per_step"]
