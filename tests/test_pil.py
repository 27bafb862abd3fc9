"""Processor-in-the-loop: the Cortex-M4F image in QEMU against a plant in Python, through semihosting FIFOs."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.shipping.artifact import load
from support.cli import assert_refused

GAINLINK = str(Path(sys.executable).with_name("gainlink"))
RTOL = 1e-4  # float32 firmware vs its float64 twin in closed loop: see tests/test_firmware_host.py


pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


@pytest.mark.parametrize("name,reference", [("pendulum", [0.5]), ("wood_berry", [1.0, -0.5])])
def test_closed_loop_matches_its_float64_twin(example_artifacts, name, reference):
    a = load(example_artifacts[name])
    steps = 1500 if name == "pendulum" else 300
    res = run_pil(
        a,
        plant=make_plant("artifact", artifact=a),
        steps=steps,
        reference=reference,
        twin=make_plant("artifact", artifact=a),
    )
    # the twin, recomputed here: the float64 law closing the loop on a fresh plant, step by step
    from gainlink.proof.reference import ReferenceLoop

    plant, law = make_plant("artifact", artifact=a), ReferenceLoop(a)
    for k in range(steps):
        y = plant.outputs()
        u = law.step(y, reference).u
        assert np.array_equal(res.twin.y[k], y) and np.array_equal(res.twin.u[k], u), k
        plant.advance(u=u)
    Y, U = res.twin.y, res.twin.u
    scale = float(np.max(np.abs(U)))
    assert float(np.max(np.abs(res.u - U))) <= RTOL * scale
    assert float(np.max(np.abs(res.y - Y))) <= RTOL * max(float(np.max(np.abs(Y))), 1e-9)
    assert 0 < res.comparison.worst_du_rel <= RTOL
    assert not np.any(res.flags & 0x01)  # no sample refused (the fault flag)
    # the loop did its job: tracked outputs settle at the reference
    tracked = a.Ci @ res.y[-1]
    assert np.allclose(tracked, reference, atol=0.02 * max(1.0, float(np.max(np.abs(reference)))))


def test_pil_cli_summary_and_files(example_artifacts, tmp_path):
    out = tmp_path / "pil"
    proc = subprocess.run(
        [
            GAINLINK,
            "pil",
            "run",
            str(example_artifacts["pendulum"]),
            "--plant",
            "artifact",
            "--steps",
            "500",
            "--reference",
            "0.2",
            "--out",
            str(out),
            "--json",
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["steps"] == 500 and summary["faults"] == 0
    assert summary["twin"]["worst_du_rel"] <= RTOL and set(summary["twin"]["iae"]) == {"r_x"}
    assert json.loads((out / "pil.json").read_text()) == summary
    rows = (out / "pil.csv").read_text().splitlines()
    assert (
        rows[0] == "y0,y1,u0,sat0,flags,sigma,twin_y0,twin_y1,twin_u0,model_y0,model_y1,model_u0" and len(rows) == 501
    )
    # the plant is the artifact's own model: the model twin differs only by the firmware's float32
    assert summary["model_twin"]["worst"] < 1e-4 and not summary["model_twin"]["warning"]
    # the report's twin plot, as a HIL report has it: one panel per output and input (2 + 1, 1.9 in each at 90 dpi)
    png = (out / "twin.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", png[16:24])
    assert (width, height) == (8 * 90, round(3 * 1.9 * 90))


def test_pil_twin_plot_shows_the_run_minus_its_twin(example_artifacts):
    """Each panel of the PIL twin plot is that signal of the run minus the twin's, over t = k Ts."""
    from gainlink.hil.loop.pil import twin_figure

    a = load(example_artifacts["wood_berry"])
    res = run_pil(
        a,
        plant=make_plant("artifact", artifact=a),
        steps=120,
        reference=[1.0, -0.5],
        twin=make_plant("artifact", artifact=a),
    )
    fig = twin_figure(res, a)
    try:
        panels = list(fig.axes)
        assert [ax.get_ylabel() for ax in panels] == [
            "x_D - twin [mol %]",
            "x_B - twin [mol %]",
            "reflux - twin [lb/min]",
            "steam - twin [lb/min]",
        ]
        assert panels[-1].get_xlabel() == "t [min]"  # the example's time unit
        expected = [res.y[:, 0] - res.twin.y[:, 0], res.y[:, 1] - res.twin.y[:, 1]]
        expected += [res.u[:, 0] - res.twin.u[:, 0], res.u[:, 1] - res.twin.u[:, 1]]
        for ax, diff in zip(panels, expected):
            line = ax.get_lines()[0]
            np.testing.assert_array_equal(line.get_xdata(), np.arange(120) * a.Ts)
            np.testing.assert_array_equal(line.get_ydata(), diff)
        assert np.any(expected[2] != 0), "float32 is not free: the plot has something to show"
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_pil_rejects_bad_arguments(example_artifacts, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # where a run would write by default
    for extra, word in ((["--reference", "1", "2"], "--reference"), (["--plant", "no_such_plant"], "no_such_plant")):
        assert_refused(("pil", "run", example_artifacts["pendulum"], "--steps", "10", *extra), word, tmp_path)


def test_pil_against_the_nonlinear_cart_pendulum(example_artifacts):
    """The firmware in QEMU balances gainlink.hil's nonlinear cart-pendulum from a 0.1 rad tilt."""
    a = load(example_artifacts["pendulum"])
    plant = make_plant("cart_pendulum", artifact=a, x0=[0.0, 0.0, 0.1, 0.0])
    twin = make_plant("cart_pendulum", artifact=a, x0=[0.0, 0.0, 0.1, 0.0])
    res = run_pil(a, plant=plant, steps=800, reference=[0.2], twin=twin)
    assert 0 < res.comparison.worst_du_rel <= RTOL and res.comparison.worst_dy_rel <= RTOL
    assert not np.any(res.flags & 0x01)  # no sample refused (the fault flag)
    assert abs(res.y[-1, 0] - 0.2) < 0.01 and abs(res.y[-1, 1]) < 0.01
    assert np.max(np.abs(res.y[:, 1])) < 0.5, "never falls over"
