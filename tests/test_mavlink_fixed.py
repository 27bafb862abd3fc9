"""The MAVLink host app runs a fixed-point artifact's own law: the integer law it certifies (not the float law of the
same export), checked in lockstep HIL over MAVLink against the bit-exact integer model (gainlink.laws.fixed.model) on
the samples the run recorded; its parameter table holds the integers it runs, and `gainlink mavlink upload` of a
re-designed set (same formats and structure; q31 and q15) writes, verifies, commits and persists them, refuses a set
for another law or other formats in one line, and rolls back a set the target refuses."""

from __future__ import annotations

import copy
import dataclasses
import re

import numpy as np
import pytest
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.qformat import real
from gainlink.laws.lq.model import Float32Loop
from gainlink.mavlink.params import INT32
from gainlink.mavlink.params import firmware_params as fixed_firmware_params
from gainlink.mavlink.upload import UploadFailed, upload
from gainlink.shipping.artifact import Artifact
from support.cli import assert_refused, run_cli
from support.fixed import example, model_run, pendulum_design
from support.mavlink import closed_loop, read_params, start_firmware
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
    assert not model.fault.any() and not tr.flags.any()
    # not the float32 law of the same export (what the MAVLink app ran before it chose the law)
    f32 = Float32Loop(a).run(Y.astype(np.float64), R.astype(np.float64))
    assert np.any(f32.u.astype(np.float32) != tr.u.astype(np.float32))
    fx = res.metrics["fixed_point"]
    assert fx["law"] == "q31" and fx["bit_exact"] is True and fx["within_per_step"]


# -- the integer gains in the parameter table: upload, verify, commit, roll back ------------------------------------


@pytest.fixture(scope="module")
def q31_app(pend_q31):
    """The MAVLink app built from the q31 pendulum."""
    from gainlink.firmware.mavlink_app import mavlink_executable

    return mavlink_executable(pend_q31[0])


@pytest.fixture(scope="module")
def retuned_q31(tmp_path_factory):
    """The q31 pendulum designed again with slightly other weights: the same formats and structure, other integers."""
    a = pendulum_design("q31", [12.0, 1.0, 110.0, 1.0])
    path = tmp_path_factory.mktemp("retuned_q31") / "gains.json"
    a.save(path)
    return a, path


def _integers(port: int) -> dict[str, int]:
    return {n: int(p.value) for n, p in read_params(port).items()}


def _model_u(a: Artifact, Y, R) -> np.ndarray:
    return real(model_run(a, Y, R).U, FixedPointLoop(a).f["u"]).astype(np.float32)


def test_the_parameter_table_holds_the_integers_the_target_runs(q31_app, pend_q31):
    a = pend_q31[0]
    fw, port = start_firmware(q31_app, None)
    try:
        params = read_params(port)
    finally:
        fw.stop()
    want = fixed_firmware_params(a)
    assert list(params) == [s.name for s in want]  # the firmware's and the ground's naming schemes agree
    assert all(p.ptype == INT32 for p in params.values())
    assert {n: int(p.value) for n, p in params.items()} == {s.name: int(s.value) for s in want}
    assert params["GL_FX_SIG"].value & 0xFFFFFFFF == int(a.checks["fixed_point"]["signature"], 16)
    assert params["GL_KX_0_0"].value == a.checks["fixed_point"]["integers"]["KX"][0][0]


def test_upload_of_a_redesigned_q31_set_commits_persists_and_the_loop_runs_it_bit_for_bit(
    q31_app, pend_q31, retuned_q31, tmp_path
):
    old, (new, new_path) = pend_q31[0], retuned_q31
    storage = tmp_path / "params.txt"
    fw, port = start_firmware(q31_app, storage)
    try:
        res = run_cli("mavlink", "upload", new_path, "--connect", f"udpout:127.0.0.1:{port}", "--persist")
        assert res.code == 0, res.err
        assert "gain set committed" in res.out and "persisted" in res.out
        assert re.search(r"^GL_KX_0_0\s+KX\[0,0\]\s+-?\d+ -> -?\d+$", res.out, re.M)
        assert _integers(port) == {s.name: int(s.value) for s in fixed_firmware_params(new)}
        Y, R, U = closed_loop(port, new, steps=150)
        u = U.astype(np.float32)
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(new, Y, R).view(np.uint32))
        assert np.any(u != _model_u(old, Y, R))  # really the new integers
    finally:
        fw.stop()
    fw, port = start_firmware(q31_app, storage)  # a restart: the integers reloaded from the stored file
    try:
        assert "loaded parameters" in fw.stderr_text()
        assert _integers(port)["GL_HASH"] == next(s.value for s in fixed_firmware_params(new) if s.name == "GL_HASH")
    finally:
        fw.stop()


def test_a_set_for_another_law_or_other_formats_is_refused_in_one_line_and_nothing_changes(
    q31_app, mavlink_exe, pend, pend_q31, tmp_path
):
    q15 = pendulum_design("q15")
    other_formats = pendulum_design("q31", [40.0, 1.0, 300.0, 2.0], [3.0])
    assert other_formats.checks["fixed_point"]["signature"] != pend_q31[0].checks["fixed_point"]["signature"]
    for art, name in ((q15, "q15.json"), (other_formats, "formats.json")):
        art.save(tmp_path / name)
    fw, port = start_firmware(q31_app, None)
    try:
        before = _integers(port)
        for path, why in (
            (pend, "the firmware runs the q31 law and the artifact is a float32 design"),
            (tmp_path / "q15.json", "the firmware runs the q31 law and the artifact is a q15 design"),
            (tmp_path / "formats.json", "the firmware's q31 law has other number formats (GL_FX_SIG "),
        ):
            res = assert_refused(("mavlink", "upload", path, "--connect", f"udpout:127.0.0.1:{port}"), why, tmp_path)
            assert "nothing was changed" in res.err, res.err
        assert _integers(port) == before
    finally:
        fw.stop()
    fw, port = start_firmware(mavlink_exe, None)  # and a q31 set to a float32 target
    try:
        argv = ("mavlink", "upload", pend_q31[1], "--connect", f"udpout:127.0.0.1:{port}")
        assert_refused(argv, "the firmware runs the float32 law and the artifact is a q31 design", tmp_path)
    finally:
        fw.stop()


def test_a_set_the_target_refuses_is_rolled_back_whole(q31_app, pend_q31, retuned_q31):
    new = retuned_q31[0]
    data = copy.deepcopy(new.data)
    data["checks"]["fixed_point"]["integers"]["F_shift"][0][0] = 70  # more than a 64-bit accumulator can shift
    bad_art = dataclasses.replace(new, data=data)
    fw, port = start_firmware(q31_app, None)
    try:
        before = _integers(port)
        with pytest.raises(UploadFailed) as err:
            upload(bad_art, connect=f"udpout:127.0.0.1:{port}")
        assert err.value.rolled_back and "commit" in str(err.value)
        assert _integers(port) == before
        Y, R, U = closed_loop(port, pend_q31[0], steps=20)  # still the compiled integers
        u = U.astype(np.float32)
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(pend_q31[0], Y, R).view(np.uint32))
    finally:
        fw.stop()


def test_q15_on_its_design_model_over_mavlink_is_bit_exact_and_its_table_holds_its_integers(tmp_path):
    """wood_berry q15 against its own linear model, 60 lockstep steps with a step; then its parameter table."""
    from gainlink.firmware.mavlink_app import mavlink_executable

    a = example("wood_berry", "q15")
    a.save(tmp_path / "gains.json")
    step = {a.signals["references"][0]: {"kind": "step", "at": 5 * a.Ts, "value": 0.5}}
    data = {"name": "wood_berry_q15", "artifact": str(tmp_path / "gains.json"), "duration": 60 * a.Ts,
            "mode": "lockstep", "controller": "firmware", "step_timeout": 2.0, "plant": {"kind": "linear"},
            "transport": {"kind": "mavlink", "port": udp_port()}, "reference": step}  # fmt: skip
    res = run_scenario(parse_scenario(data, path=tmp_path / "scenario.toml"))
    fx = res.metrics["fixed_point"]
    assert res.complete and fx["law"] == "q15" and fx["bit_exact"] is True and fx["certificate_applies"] is True
    assert fx["unsaturated_steps"] == 60 and fx["within_per_step"]
    assert np.all(np.array(fx["measured_du_design"]) <= np.array(fx["certified_du_design"]))
    fw, port = start_firmware(mavlink_executable(a), None)
    try:
        assert _integers(port) == {s.name: int(s.value) for s in fixed_firmware_params(a)}
    finally:
        fw.stop()


def test_upload_of_a_redesigned_q15_set_commits_and_the_loop_runs_it_bit_for_bit(tmp_path):
    """q15 (16-bit coefficients and commands): the pendulum with the q31 redesign's weights keeps its formats."""
    from gainlink.firmware.mavlink_app import mavlink_executable

    old, new = pendulum_design("q15"), pendulum_design("q15", [12.0, 1.0, 110.0, 1.0])
    assert new.checks["fixed_point"]["signature"] == old.checks["fixed_point"]["signature"]
    new.save(tmp_path / "gains.json")
    fw, port = start_firmware(mavlink_executable(old), None)
    try:
        res = run_cli("mavlink", "upload", tmp_path / "gains.json", "--connect", f"udpout:127.0.0.1:{port}")
        assert res.code == 0, res.err
        assert "gain set committed" in res.out
        assert _integers(port) == {s.name: int(s.value) for s in fixed_firmware_params(new)}
        Y, R, U = closed_loop(port, new, steps=150)
        u = U.astype(np.float32)
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(new, Y, R).view(np.uint32))
        assert np.any(u != _model_u(old, Y, R))  # really the new integers
    finally:
        fw.stop()
