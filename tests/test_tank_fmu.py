"""The project's tank FMU (hil/fmus/tank): the nonlinear tank of examples/tank_scheduled.toml and
examples/tank_showcase.toml as C, the same equations as the built-in ``kind = "tank"`` plant.

Oracles: the analytic linearisation at a level h0 (trim q = u = c sqrt(h0); dh/dt = (q - c/(2 sqrt(h0)) h) / a0
with a0 = area + flare h0), python-control's poles of it for the >= 5x claim, and the Python plant (an independent
implementation of the same equations) driven by the same commands.
"""

from __future__ import annotations

import logging

import control as ct
import numpy as np
import pytest
from gainlink.fileio import read_toml
from gainlink.hil.plants.build import build_fmu
from gainlink.hil.plants.config import plant_from_config
from support.cli import run_cli
from support.paths import EXAMPLES

C, TAU = 0.4, 0.1
SHOWCASE = {"area": 0.2, "flare": 2.0}  # examples/tank_showcase.toml widens with its level


def analytic(h0: float, area: float = 1.0, flare: float = 0.0) -> dict:
    """The tank linearised by hand at level ``h0``."""
    a0 = area + flare * h0
    q0 = C * np.sqrt(h0)
    A = [[-1 / TAU, 0.0], [1 / a0, -C / (2 * np.sqrt(h0)) / a0]]
    return {"A": A, "B": [[1 / TAU], [0.0]], "C": [[0.0, 1.0]], "u_op": [q0], "y_op": [h0], "x_op": [q0, h0]}


def _linearized(tmp_path, example: str, *at: str) -> tuple[dict, dict]:
    """``gainlink linearize tank --schedule h=<the example's points>``; the written spec and the example."""
    ex, _ = read_toml(EXAMPLES / f"{example}.toml", what="spec", error=ValueError)
    points = ",".join(repr(float(v)) for v in ex["schedule"]["points"])
    out = tmp_path / "spec.toml"
    extra = [a for name in at for a in ("--at", name)]
    res = run_cli("linearize", "tank", "--schedule", f"h={points}", *extra, "--Ts", "0.05", "--out", out)
    assert res.code == 0, res.err
    assert "poor" not in res.err.lower()
    return read_toml(out, what="spec", error=ValueError)[0], ex


@pytest.mark.parametrize(
    ("example", "params"),
    [("tank_scheduled", {}), ("tank_showcase", SHOWCASE)],
)
def test_linearize_schedule_trims_the_fmu_at_each_level_as_derived_by_hand(tmp_path, example, params, caplog):
    caplog.set_level(logging.INFO)
    spec, ex = _linearized(tmp_path, example, *(f"{k}={v}" for k, v in params.items()))
    # each point is trimmed from its own guesses: the FMU's start point (the same for every level) is no news, and
    # "the start point is not an equilibrium ... states [0.08 0.04]" once per level said the points were that one
    assert not [r.getMessage() for r in caplog.records if "equilibrium" in r.getMessage()]
    assert [r.getMessage().split(" in ")[0] for r in caplog.records if r.getMessage().startswith("trimmed")] == [
        f"trimmed h = {h:g}" for h in ex["schedule"]["points"]
    ]
    assert spec["plant"]["states"] == ["q", "h"] and spec["schedule"]["sigma"] == "h"
    for h0, got, written in zip(ex["schedule"]["points"], spec["schedule"]["plant"], ex["schedule"]["plant"]):
        want = analytic(h0, **params)
        for key in ("A", "B", "C", "u_op", "y_op", "x_op"):
            assert np.allclose(got[key], want[key], rtol=1e-9, atol=1e-12), (h0, key)
            assert np.allclose(written[key], want[key], rtol=1e-12, atol=1e-15), (h0, key)  # the example's own
        assert got["fit"]["h"]["nrmse"] < 0.01


CASES = [("tank_scheduled", {}, 5.0), ("tank_showcase", SHOWCASE, 50.0)]


@pytest.mark.parametrize(("example", "params", "at_least"), CASES)
def test_the_local_dynamics_change_by_at_least_5x_across_the_envelope(example, params, at_least):
    """The level's pole (python-control on each point's linearisation) moves by the factor the examples state."""
    ex, _ = read_toml(EXAMPLES / f"{example}.toml", what="spec", error=ValueError)
    lo, hi = ex["schedule"]["points"][0], ex["schedule"]["points"][-1]
    models = (analytic(lo, **params), analytic(hi, **params))
    slow = [min(abs(ct.poles(ct.ss(p["A"], p["B"], p["C"], 0)))) for p in models]
    assert slow[0] / slow[1] >= at_least


@pytest.mark.parametrize("interface", ["cs", "me"])
def test_the_fmu_is_the_python_tank_and_never_goes_below_empty(interface):
    """Filled at 0.3 for 10 s, then the pump off for 10 s: the FMU follows the built-in plant (Co-Simulation's
    RK4 to 1e-7 m, CVode to 1e-5 m), and the drained tank stays at (Co-Simulation: exactly) zero."""
    params = {"area": 0.2, "flare": 2.0}
    fmu = plant_from_config({"kind": "fmu", "fmu": "tank", "interface": interface, "parameters": params})
    ref = plant_from_config({"kind": "tank", "parameters": params, "step": 0.005})
    try:
        assert fmu.state_names == ("q", "h") and fmu.output_names == ("h",)
        for plant in (fmu, ref):
            plant.reset(initial={"q": 0.08, "h": 0.04})
        got = []
        for k in range(400):
            u = np.array([0.3 if k < 200 else 0.0])
            for plant in (fmu, ref):
                plant.advance(u=u, dt=0.05)
            got.append((fmu.outputs()[0], ref.outputs()[0]))
    finally:
        fmu.close()
    y = np.array(got)
    assert np.max(np.abs(y[:, 0] - y[:, 1])) < (1e-7 if interface == "cs" else 1e-5)
    assert y[199, 0] > 0.5 and y[-1, 1] == 0.0
    assert (y[:, 0].min() == 0.0) if interface == "cs" else (y[:, 0].min() > -1e-6)


def test_the_fmu_is_built_from_its_sources():
    from fmpy import read_model_description

    md = read_model_description(str(build_fmu("tank")))
    bounds = {v.name: (v.min, v.max) for v in md.modelVariables if v.causality == "parameter"}
    assert set(bounds) == {"c", "tau_p", "area", "flare", "step_max"}
    assert all(lo is not None and hi is not None for lo, hi in bounds.values())
