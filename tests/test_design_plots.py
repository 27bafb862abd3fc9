"""``gainlink design --plots DIR``: the loop broken at each actuator (Bode, margins marked) and the closed-loop step,
drawn with python-control.

Oracle: two independent accounts of the same margins agree, python-control's ``stability_margins`` of the loop the
plots build from the artifact (plant and law as python-control systems, the other inputs' loops closed) and the
design's own ``checks.margins`` (gainlink's closed-loop matrices and exact gain limits); and python-control's poles
of that loop closed with its gain 0.2 dB inside and outside each of the design's gain margins are stable and not.
On the pendulum (one input) and the Wood-Berry column (two, each broken with the other closed: one of them crosses
-180 degrees twice, and the margin is the nearer). A unit reference step ends with the tracked output at 1."""

from __future__ import annotations

import os
import stat

import control as ct
import numpy as np
import pytest
from gainlink.shipping.artifact import load
from gainlink.synthesis.loop_plots import broken_loop, loop_margins
from support.cli import assert_refused, run_cli
from support.paths import EXAMPLES


@pytest.mark.parametrize("name", ["pendulum", "wood_berry"])
def test_the_plotted_loops_margins_are_the_designs(example_artifacts, name):
    a = load(example_artifacts[name])
    for i, row in enumerate(a.checks["margins"]):
        loop = broken_loop(a, i)
        m = loop_margins(a, i, loop)
        crossings = [20 * np.log10(g) for g, _ in m.gain_margins if np.isfinite(g) and g > 0]
        up = min((g for g in crossings if g > 0), default=None)
        down = max((g for g in crossings if g < 0), default=None)
        for got, want in ((up, row["gain_margin_up_db"]), (down, row["gain_margin_down_db"])):
            assert (got is None) == (want is None) and (want is None or abs(got - want) < 0.01), (name, row, got)
            if want is not None:
                inside, outside = want - np.sign(want) * 0.2, want + np.sign(want) * 0.2
                assert _stable(loop, inside) and not _stable(loop, outside), (name, row["input"], want)
        if row["phase_margin_deg"] is None:
            assert m.phase_margin_deg is None
        else:
            assert m.phase_margin_deg == pytest.approx(row["phase_margin_deg"], abs=0.05), (name, row["input"])
            assert m.gain_crossover_rad_s == pytest.approx(row["gain_crossover_rad_s"], rel=1e-3)
        assert _stable(loop, 0.0)  # closing it (1 + L) is the design's closed loop


def _stable(loop, gain_db: float) -> bool:
    return bool(np.all(np.abs(ct.poles(ct.feedback(10 ** (gain_db / 20) * loop, 1))) < 1.0))


def test_design_plots_writes_readable_pngs_atomically(tmp_path):
    out, plots = tmp_path / "design", tmp_path / "plots"
    res = run_cli("design", EXAMPLES / "pendulum.toml", "--out", out, "--plots", plots)
    assert res.code == 0, res.err
    assert sorted(p.name for p in plots.iterdir()) == ["loop_F.png", "step.png"]  # no temporary file left
    umask = os.umask(0)
    os.umask(umask)
    for png in plots.iterdir():
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert stat.S_IMODE(png.stat().st_mode) == 0o666 & ~umask  # as open() would make it (0644 under 022)
    assert f"plots in {plots}: loop_F.png, step.png" in res.out
    a = load(out / "gains.json")
    cl = a.closed_loop()
    assert ct.dcgain(cl)[a.signals["outputs"].index("x"), cl.input_labels.index("r_x")] == pytest.approx(1.0)


def test_plots_into_a_file_is_one_line_and_nothing_written(tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("keep")
    argv = ("design", EXAMPLES / "pendulum.toml", "--out", tmp_path / "design", "--plots", taken)
    assert_refused(argv, f"--plots {taken} exists and is not a directory", tmp_path)
