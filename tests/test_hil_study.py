"""The saturation study: the pendulum example designed with anti-windup none, clamp and backcalc, each
run through the firmware's CAN node against the nonlinear pendulum FMU from 1 m off its reference.

The first commands hit the example's +-20 N limits. The expected ordering is the textbook one for
overshoot: back-calculation bleeds the integrator while the command is clamped, so the cart does not
swing past its reference; without anti-windup it does.
"""

from __future__ import annotations

import json

import pytest
from gainlink.hil.loop.study import default_study, run_saturation_study
from support.hil import udp_transport

pytestmark = pytest.mark.slow


def test_backcalc_reduces_overshoot_against_none(tmp_path):
    study = default_study()
    assert study["controller"] == "firmware" and study["plant"] == {"kind": "fmu", "fmu": "cart_pendulum"}
    report = tmp_path / "study"
    result = run_saturation_study(report_dir=report, transport=udp_transport(fd=True))
    table = result.table
    assert list(table) == ["none", "clamp", "backcalc"]
    for mode, row in table.items():
        assert row["complete"] and row["lost"] == 0, mode
        assert row["saturation_fraction"]["F"] > 0, f"{mode} never saturated"
        assert row["inputs_peak_abs"]["F"] == pytest.approx(20.0), mode
        assert abs(row["outputs_final"]["theta"]) < 0.01 and abs(row["outputs_final"]["x"]) < 0.05, mode
    assert table["backcalc"]["overshoot_pct"] < table["none"]["overshoot_pct"] - 20.0
    assert table["clamp"]["overshoot_pct"] <= table["none"]["overshoot_pct"]
    saved = json.loads((report / "study.json").read_text())
    assert saved["modes"]["backcalc"]["overshoot_pct"] == table["backcalc"]["overshoot_pct"]
    for mode in table:
        assert json.loads((report / mode / "report.json").read_text())["complete"] is True
        assert (report / mode / "gains.json").is_file()
        assert [p.read_bytes()[:4] for p in (report / mode).glob("*.png")].count(b"\x89PNG") >= 2, mode
    assert (report / "comparison.png").read_bytes()[:4] == b"\x89PNG"
    assert "lowest overshoot: backcalc" in result.summary


def test_backcalc_catches_a_kicked_pendulum_that_none_and_clamp_lose(tmp_path):
    """(Without plots, as `gainlink hil study --no-plots`: the reports and the table, no PNG.)"""
    report = tmp_path / "kick"
    result = run_saturation_study(
        report_dir=report, transport=udp_transport(fd=True), study=default_study("saturation_kick"), plots=False
    )
    assert (report / "study.json").is_file() and (report / "backcalc" / "report.json").is_file()
    assert list(report.rglob("*.png")) == []
    table = result.table
    for mode in ("none", "clamp"):  # the command stays pinned at a limit and the pendulum falls
        assert table[mode]["outputs_peak_abs"]["theta"] > 1.57, mode
        assert table[mode]["saturation_fraction"]["F"] > 0.5, mode
    back = table["backcalc"]
    assert back["outputs_peak_abs"]["theta"] < 1.0 and abs(back["outputs_final"]["theta"]) < 0.01
    assert 0 < back["saturation_fraction"]["F"] < 0.05 and abs(back["outputs_final"]["x"]) < 0.05
    assert "lowest IAE: backcalc" in result.summary


def test_the_cli_passes_no_plots_to_the_study(monkeypatch, tmp_path):
    """`gainlink hil study --no-plots` asks the study for no plots (the study itself is the test above)."""
    import gainlink.hil.loop.study as study_mod
    from support.cli import run_cli

    seen = {}

    def fake_study(**kwargs):
        seen.update(kwargs)
        return study_mod.StudyResult(runs={}, table={}, summary="")

    monkeypatch.setattr(study_mod, "run_saturation_study", fake_study)
    for extra, plots in (([], True), (["--no-plots"], False)):
        assert run_cli("hil", "study", "--report", tmp_path / "r", *extra).code == 0
        assert seen["plots"] is plots
