"""The CAN node runs the artifact's own law: the integer law of a fixed-point artifact (not the float law of the same
export), checked over the bus (python-can udp_multicast, the real gainlink_can process) against the bit-exact
integer model on the samples the run recorded; the HIL report says which law ran and what it cost against the
float64 law, beside the certified bounds."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gainlink.hil import run as hil_run
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.qformat import real
from gainlink.laws.lq.model import Float32Loop
from gainlink.shipping.artifact import load
from gainlink.shipping.can_layout import layout_for
from support.fixed import example, model_run
from support.hil import pendulum_scenario, udp_transport


@pytest.fixture(scope="module")
def pend_q31(tmp_path_factory):
    """The pendulum designed in q31, saved, with its CAN node built."""
    from gainlink.hil.links.can_firmware import firmware_can_executable

    a = example("pendulum", "q31")
    path = tmp_path_factory.mktemp("q31") / "gains.json"
    a.save(path)
    firmware_can_executable(a)
    return a, path


def _fixed_run(pend_q31, cart_fmu, tmp_path, **extra):
    path = pend_q31[1]
    data = pendulum_scenario(
        gains=path,
        fmu=cart_fmu,
        transport=udp_transport(fd=False),
        duration=2.0,
        reference={"r_x": {"kind": "step", "at": 0.5, "value": 0.2}},
        noise={"theta": 1e-4},
        seed=5,
        **extra,
    )
    report = tmp_path / "report"
    return hil_run(data, report=report, plots=False), report


def test_q31_over_can_is_the_integer_law_bit_for_bit_on_the_recorded_samples(pend_q31, cart_fmu, tmp_path):
    a, _ = pend_q31
    res, _ = _fixed_run(pend_q31, cart_fmu, tmp_path)
    tr = res.trace
    assert res.complete and res.metrics["lost"] == 0 and tr.t.size == 200
    assert "law=q31" in res.info["controller"]["ready"]
    # The oracle: the integer model (gainlink.laws.fixed.model) on the float32 samples the run sent, from the start.
    Y, R = tr.y.astype(np.float32), tr.r.astype(np.float32)
    model = model_run(a, Y, R)
    u_model = real(model.U, FixedPointLoop(a).f["u"]).astype(np.float32)
    np.testing.assert_array_equal(tr.u.astype(np.float32).view(np.uint32), u_model.view(np.uint32))
    sat = np.sum(tr.sat.astype(np.int64) << np.arange(a.m), axis=1)
    np.testing.assert_array_equal(sat, model.sat)
    assert not model.fault.any() and not tr.flags.any()
    # ... and not the float32 law of the same export (what the node ran before it chose the law).
    f32 = Float32Loop(a).run(Y.astype(np.float64), R.astype(np.float64))
    assert np.any(f32.u.astype(np.float32) != tr.u.astype(np.float32))


def test_q31_hil_report_states_the_law_and_its_deviation_beside_the_certified_bound(pend_q31, cart_fmu, tmp_path):
    a, _ = pend_q31
    _, report = _fixed_run(pend_q31, cart_fmu, tmp_path)
    fx = json.loads((report / "report.json").read_text())["fixed_point"]
    err = a.checks["fixed_point"]["error"]
    assert fx["law"] == "q31" and fx["numeric"] == "q31" and fx["bit_exact"] is True
    # per step against the float64 law with the quantised coefficients: the rounding alone
    assert fx["certified_du_per_step"] == err["per_step_rounding"] and fx["certified_du_design"] == err["certified"]
    assert fx["unsaturated_steps"] > 100
    assert 0 < fx["measured_du_per_step"][0] <= err["per_step_rounding"][0] and fx["within_per_step"]
    assert fx["measured_du_design"][0] > 0 and fx["certificate_applies"] is False  # the FMU is not the model
    assert fx["overflow_steps"] == 0
    summary = (report / "summary.txt").read_text()
    assert "law ran: q31 (artifact q31): bit for bit the integer model" in summary
    assert "certified <= " in summary


def test_a_float32_artifact_names_its_law_and_gets_no_fixed_point_block(pend, can_firmware, cart_fmu):
    res = hil_run(pendulum_scenario(gains=pend, fmu=cart_fmu, transport=udp_transport(fd=True), duration=0.3))
    assert res.complete and "law=float32 wire=4" in res.info["controller"]["ready"]
    assert "fixed_point" not in res.metrics


def test_the_dbc_names_the_status_bits_of_the_law_the_node_runs(pend_q31, pend):
    """The command frames' status signal carries a value table of the bits the law can set, at docs/design.md's
    positions (written out here): the integer law's clipped and overflow bits, none of them for the float32 law."""
    import cantools

    def table(a) -> dict[int, str]:
        db = cantools.database.load_string(layout_for(a).dbc(), database_format="dbc")
        command = next(m for m in db.messages if m.senders == ["controller"])
        return {int(k): str(v) for k, v in command.get_signal_by_name("status").choices.items()}

    fixed, plain = table(pend_q31[0]), table(load(pend))
    assert {0x01: "FAULT", 0x04: "CLIPPED", 0x08: "OVERFLOW"}.items() <= fixed.items()
    assert 0x04 not in plain and 0x08 not in plain and plain[0x01] == "FAULT" and plain[0x80] == "RESET"


def test_q15_on_the_design_model_is_bit_exact_and_within_the_certified_bounds(tmp_path):
    """wood_berry q15 against its own linear model (the loop the certificate is about), 60 steps with a step."""
    a = example("wood_berry", "q15")
    a.save(tmp_path / "gains.json")
    step = {a.signals["references"][0]: {"kind": "step", "at": 5 * a.Ts, "value": 0.5}}
    data = {"name": "wood_berry_q15", "artifact": str(tmp_path / "gains.json"), "duration": 60 * a.Ts,
            "controller": "firmware", "step_timeout": 2.0, "plant": {"kind": "linear"},
            "transport": udp_transport(fd=True), "reference": step}  # fmt: skip
    fx = hil_run(data).metrics["fixed_point"]
    assert fx["law"] == "q15" and fx["bit_exact"] is True and fx["certificate_applies"] is True
    assert fx["unsaturated_steps"] == 60 and fx["within_per_step"]
    assert np.all(np.array(fx["measured_du_design"]) <= np.array(fx["certified_du_design"]))
