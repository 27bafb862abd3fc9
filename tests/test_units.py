"""Units: a spec's ``[units]`` says what each signal is measured in (and ``time`` the unit of Ts); the artifact
carries them in ``signals.units`` and every plot axis and summary figure says them. Labels only: the law is the
same, and an artifact whose spec gives none is byte for byte what it was (no ``units`` key)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from gainlink.errors import ArtifactError
from gainlink.hil.loop.pil_report import pil_summary_text
from gainlink.shipping.artifact import from_dict, load, seal
from gainlink.synthesis.loop_plots import _bode_figure, _step_figure
from support.cli import GOOD_SPEC, assert_refused, run_cli


def test_the_examples_units_reach_the_artifact_and_its_labels(example_artifacts):
    a = load(example_artifacts["pendulum"])
    assert a.signals["units"] == {"F": "N", "theta": "rad", "theta_dot": "rad/s", "x": "m", "x_dot": "m/s"}
    assert (a.label("x"), a.label("F"), a.unit("r_x"), a.unit("time")) == ("x [m]", "F [N]", "m", "s")
    wb = load(example_artifacts["wood_berry"])
    assert (wb.unit("time"), wb.label("x_D"), wb.label("x3")) == ("min", "x_D [mol %]", "x3")  # a state without one


def test_the_design_plots_axes_carry_the_units(example_artifacts):
    a = load(example_artifacts["pendulum"])
    step = _step_figure(a)
    assert [ax.get_ylabel() for ax in step.axes] == ["x [m] (output)", "theta [rad] (output)", "F [N] (command)"]
    assert step.axes[-1].get_xlabel() == "t [s]"
    wb = load(example_artifacts["wood_berry"])  # time in minutes: so are the frequencies
    assert _step_figure(wb).axes[-1].get_xlabel() == "t [min]"
    assert _bode_figure(wb, 0).axes[1].get_xlabel() == "frequency [rad/min] (Nyquist 3.142 rad/min)"


def test_the_pil_summary_gives_every_figure_its_unit(example_artifacts):
    a = load(example_artifacts["pendulum"])
    twin = {
        "inputs": {"F": {"max_du": 2e-6, "max_du_rel": 5e-8}},
        "outputs": {"x": {"max_dy": 3e-7, "max_dy_rel": 1e-6}, "theta": {"max_dy": 1e-7, "max_dy_rel": 6e-7}},
        "iae": {"r_x": {"real": 0.25, "twin": 0.25, "difference": 0.0, "difference_rel": 0.0}},
    }
    summary = {"artifact": "pendulum", "sha256": a.sha256, "law": "float32", "target": "cortex-m4",
               "board": "mps2-an386", "plant": "artifact", "steps": 10, "saturated_steps": 0, "faults": 0,
               "steps_per_second": 5000.0,
               "round_trip_us_p50": 40.0, "round_trip_us_p99": 90.0, "final_output": [0.1, -0.02],
               "twin": twin}  # fmt: skip
    text = pil_summary_text(summary, artifact=a)
    assert "F 2e-06 N (5e-08 of span)" in text and "x 3e-07 m" in text and "theta 1e-07 rad" in text
    assert (
        "law float32" in text and "r_x 0.25 m s vs 0.25" in text and "final outputs: x 0.1 m, theta -0.02 rad" in text
    )


def test_a_spec_without_units_writes_no_units_key(tmp_path):
    spec = tmp_path / "s.toml"
    spec.write_text(GOOD_SPEC)
    assert run_cli("design", spec, "--out", tmp_path / "out").code == 0
    data = json.loads((tmp_path / "out" / "gains.json").read_text())
    assert "units" not in data["signals"]  # so every artifact designed before keeps its sha256


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ('[units]\nx00 = "m"\n', "units names 'x00', which is not a plant signal (did you mean 'x0'?)"),
        ('[units]\nx0 = ""\n', "units.x0 must be a unit of 1 to 16 characters on one line"),
        ("[units]\nx0 = 3\n", "units.x0 must be a unit of 1 to 16 characters on one line"),
    ],
)
def test_a_bad_units_table_is_one_line(tmp_path, table, words):
    spec = tmp_path / "s.toml"
    spec.write_text(GOOD_SPEC + table)
    assert_refused(("design", spec, "--out", tmp_path / "out"), words, tmp_path)


def test_an_artifact_whose_units_name_no_signal_is_refused(example_artifacts):
    data = copy.deepcopy(load(example_artifacts["pendulum"]).data)
    data["signals"]["units"]["speed"] = "m/s"
    with pytest.raises(ArtifactError, match=r"signals\.units names 'speed'"):
        from_dict(seal(data))
    assert np.isfinite(load(example_artifacts["pendulum"]).K).all()
