"""A third-party FMU in the bridge: OpenModelica's Mass_Damper from the gemseo-fmu wheel (fetched at test time,
pinned by sha256). Model Exchange through fmpy's CVode, variable mapping refusals, and the whole chain:
linearise, design (with the FMU's operating point y_op = -0.5, and without), HIL against the host firmware over
udp_multicast in lockstep, tracking a reference.

Oracle: the model's own parameters (mass.m, spring.c with rest length spring.s_rel0, damper.d) in the
textbook equation of a mass on a spring and a damper, m s'' = -c (s - s0) - d s' - f, for the state
s = damper.s_rel (the output is y = 0.5 - s, so that the force f pulls y up: B = -1/m for s'').
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import PlantError
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.hil.plants.config import plant_from_config
from scipy.linalg import expm
from support.cli import run_cli
from support.hil import udp_transport
from support.thirdparty import TEMPLATE, gemseo_fmu

pytestmark = pytest.mark.slow  # started first (tests/conftest.py)


@pytest.fixture(scope="module")
def mass_damper():
    return gemseo_fmu("Mass_Damper.fmu")


def _physics(c=1.0e4, d=10.0, m=1.0):
    A = np.array([[0.0, 1.0], [-c / m, -d / m]])
    B = np.array([[0.0], [-1.0 / m]])
    return A, B


def _exact(A, B, x0, u, dt):
    """ZOH solution of the deviation x - (1, 0) under the held inputs u."""
    big = np.zeros((3, 3))
    big[:2, :2], big[:2, 2:] = A, B
    E = expm(big * dt)
    xs, x = [], np.asarray(x0, float) - [1.0, 0.0]
    for uk in u:
        x = E[:2, :2] @ x + E[:2, 2] * uk
        xs.append(x + [1.0, 0.0])
    return np.array(xs)


@pytest.mark.parametrize("parameters, c", [({}, 1.0e4), ({"spring.c": 4.0e3}, 4.0e3)])
def test_model_exchange_plant_integrates_the_mass_damper_exactly(mass_damper, parameters, c):
    plant = plant_from_config({"kind": "fmu", "path": str(mass_damper), "interface": "me", "parameters": parameters})
    try:
        assert plant.input_names == ("f",) and plant.output_names == ("y",)
        assert plant.state_names == ("damper.s_rel", "damper.v_rel")
        x0 = plant.state()
        dt, u = 1e-3, 100.0 * np.sin(30.0 * np.arange(300) * 1e-3)
        xs, ys = [], []
        for uk in u:
            plant.advance(u=np.array([uk]), dt=dt)
            xs.append(plant.state())
            ys.append(plant.outputs()[0])
        exact = _exact(*_physics(c=c), x0, u, dt)
        # CVode at rtol 1e-8 against the matrix exponential: |s| ~ 0.5, |v| ~ 50 m/s.
        np.testing.assert_allclose(np.array(xs)[:, 0], exact[:, 0], rtol=0, atol=1e-5)
        np.testing.assert_allclose(ys, 0.5 - exact[:, 0], rtol=0, atol=1e-5)
        with pytest.raises(PlantError, match="cannot get/set its state"):
            plant.save_state()
    finally:
        plant.close()


@pytest.mark.parametrize(
    "config, message",
    [
        ({"inputs": ["force"]}, "has no variable named 'force' (for inputs)"),
        ({"inputs": ["damper.useHeatPort"]}, "variable 'damper.useHeatPort' is Boolean, but inputs must be Real"),
        ({"outputs": ["damper.stateSelect"]}, "variable 'damper.stateSelect' is Enumeration, but outputs must be Real"),
        ({"inputs": ["spring.c"]}, "spring.c is not an input (causality parameter)"),
        ({"outputs": []}, "has no Real output to sample"),
        ({"parameters": {"mass.mass": 2.0}}, "has no variable 'mass.mass' to set"),
        ({"parameters": {"damper.useHeatPort": 1.5}}, "'damper.useHeatPort' is Boolean; 1.5 is not a value"),
        ({"interface": "me", "states": ["mass.m_kg"]}, "no variable named 'mass.m_kg' (for states)"),
        ({"interface": "quantum"}, "interface must be auto, cs or me"),
        ({"interface": "cs", "rtol": 1e-6}, "rtol and max_step set fmpy's solver"),
    ],
)
def test_bad_mappings_are_refused_in_one_line(mass_damper, config, message):
    with pytest.raises(PlantError) as err:
        plant_from_config({"kind": "fmu", "path": str(mass_damper), **config})
    assert message in str(err.value) and "\n" not in str(err.value)


def test_an_fmu_without_an_input_is_refused():
    with pytest.raises(PlantError) as err:
        plant_from_config({"kind": "fmu", "path": str(gemseo_fmu("ramp.fmu"))})
    assert "FMU ramp has no Real input to drive" in str(err.value)


@pytest.mark.parametrize("operating_point", [True, False], ids=["y_op", "no_op"])
def test_linearise_design_and_hil_track_a_reference_on_the_thirdparty_fmu(mass_damper, tmp_path, operating_point):
    (tmp_path / "template.toml").write_text(TEMPLATE, "utf-8")
    spec = tmp_path / "mass_damper.toml"
    res = run_cli("linearize", mass_damper, "--Ts", "0.001", "--out", spec, "--template", tmp_path / "template.toml")
    assert res.code == 0, res.err
    from gainlink.spec import load_spec

    s = load_spec(spec)
    A, B = _physics()
    np.testing.assert_allclose(s.plant.A, A, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(s.plant.B, B, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(s.plant.C, [[-1.0, 0.0]], atol=1e-9)
    # linearize writes the FMU's rest point: f = 0 holds the mass where the spring is unloaded, y = -0.5
    # (its output's start value)
    import tomllib

    from gainlink.hil.plants import toml_write

    data = tomllib.loads(spec.read_text())
    assert data["operating_point"]["u_op"] == {"f": 0.0} and data["operating_point"]["y_op"] == {"y": -0.5}
    if not operating_point:  # the same spec with its [operating_point] table removed
        del data["operating_point"]
        spec.write_text(toml_write.dumps(data))
    res = run_cli("design", spec, "--out", tmp_path)
    assert res.code == 0, res.err
    r = run_scenario(
        parse_scenario(
            {
                "name": "mass_damper_hil",
                "artifact": str(tmp_path / "gains.json"),
                "duration": 1.0,
                "mode": "lockstep",
                "controller": "firmware",
                "step_timeout": 2.0,
                "peer_timeout": 4.0,
                "transport": udp_transport(),
                "plant": {"kind": "fmu", "path": str(mass_damper), "interface": "me"},
                "reference": {"r_y": {"kind": "step", "at": 0.3, "initial": -0.5, "value": -0.45}},
            }
        )
    )
    m = r.metrics
    assert r.complete and m["steps"] == 1000 and m["lost"] == 0
    assert m["outputs_final"]["y"] == pytest.approx(-0.45, abs=1e-3)
    assert m["tracked"]["r_y"]["settling_time_s"] is not None and m["tracked"]["r_y"]["settling_time_s"] < 0.6
    assert m["twin"]["inputs"]["f"]["max_du"] < 1e-3 * 2000.0  # the C loop is its float64 twin, to float32
    # Holding y 0.05 m above the rest point takes the spring's force c * 0.05 = 500 N.
    assert r.trace.u[-1, 0] == pytest.approx(1.0e4 * 0.05, rel=1e-2)
    if operating_point:
        assert m["saturation_fraction"]["f"] == 0.0
    else:
        # Without the trim the loop reads the absolute y as a deviation: the integrator still removes the offset
        # (y tracks), but the start-up transient drives the force into its limits.
        assert m["saturation_fraction"]["f"] > 0.01
