"""An FMI 3.0 Model-Exchange-only FMU built from the project's own C sources (hil/fmus/mass_spring_damper3):
the plant integrates it, linearize reads it, and the CLI writes a spec from it (both were refused before).

Oracle: the hand-derived mass-spring-damper, m s'' = f - c (s - s0) - d s', with the FMU's declared parameters
(m 2 kg, c 50 N/m, d 3 N s/m, s0 0.5 m), solved exactly under a held input with scipy's matrix exponential.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import PlantError
from gainlink.hil.plants.build import build_fmu
from gainlink.hil.plants.config import plant_from_config
from gainlink.hil.plants.linearize import linearize
from scipy.linalg import expm
from support.cli import run_cli

MASS, C, D, S0 = 2.0, 50.0, 3.0, 0.5


def physics(c: float = C) -> tuple[np.ndarray, np.ndarray]:
    return np.array([[0.0, 1.0], [-c / MASS, -D / MASS]]), np.array([[0.0], [1.0 / MASS]])


def exact_positions(u: np.ndarray, dt: float, *, c: float = C, x0=(0.0, 0.0)) -> np.ndarray:
    """Deviation of s from s0 after each held input, by the matrix exponential of [[A, B], [0, 0]]."""
    A, B = physics(c)
    big = np.zeros((3, 3))
    big[:2, :2], big[:2, 2:] = A, B
    E = expm(big * dt)
    x, out = np.asarray(x0, float), []
    for uk in u:
        x = E[:2, :2] @ x + E[:2, 2] * uk
        out.append(x[0])
    return np.array(out)


@pytest.fixture(scope="module")
def msd3():
    return build_fmu("mass_spring_damper3")


def test_it_is_an_fmi3_model_exchange_only_fmu(msd3):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(msd3)) == []
    md = read_model_description(str(msd3))
    assert md.fmiVersion == "3.0" and md.modelExchange is not None and md.coSimulation is None


@pytest.mark.parametrize("parameters, c", [({}, C), ({"c": 80.0}, 80.0)])
def test_the_plant_integrates_it_exactly(msd3, parameters, c):
    plant = plant_from_config({"kind": "fmu", "path": str(msd3), "parameters": parameters})
    try:
        assert plant.interface == "me"  # auto: the only interface it has
        assert plant.input_names == ("f",) and plant.output_names == ("s",) and plant.state_names == ("s", "v")
        dt = 0.01
        u = 10.0 * np.sin(0.5 * np.arange(400) * dt) + 4.0 * (np.arange(400) > 200)
        ys = []
        for uk in u:
            plant.advance(u=np.array([uk]), dt=dt)
            ys.append(plant.outputs()[0])
        # CVode at rtol 1e-8 against the matrix exponential: |s - s0| reaches ~0.3 m.
        np.testing.assert_allclose(np.array(ys) - S0, exact_positions(u, dt, c=c), rtol=0, atol=2e-5)
        snap = plant.save_state()  # canGetAndSetFMUState: a snapshot restores the state exactly
        plant.advance(u=np.array([1.0]), dt=dt)
        ahead = plant.outputs()
        plant.restore_state(snap)
        plant.advance(u=np.array([1.0]), dt=dt)
        assert np.array_equal(plant.outputs(), ahead)
    finally:
        plant.close()


def test_forcing_cosimulation_on_it_is_refused_in_one_line(msd3):
    with pytest.raises(PlantError) as err:
        plant_from_config({"kind": "fmu", "path": str(msd3), "interface": "cs"})
    assert "has no Co-Simulation interface" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("method", ["auto", "differences"])
def test_linearize_reads_its_derivatives(msd3, method):
    lin = linearize(msd3, method=method)
    A, B = physics()
    np.testing.assert_allclose(lin.A, A, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(lin.B, B, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(lin.C, [[1.0, 0.0]], atol=1e-9)
    np.testing.assert_allclose(lin.D, [[0.0]], atol=1e-12)
    assert lin.method == ("directional derivatives" if method == "auto" else "central differences")


def test_linearize_finds_the_equilibrium_a_held_force_makes(msd3):
    lin = linearize(msd3, at={"c": 80.0, "f": 8.0})  # rest where the spring holds the force: s0 + f / c
    np.testing.assert_allclose(lin.x0, [S0 + 8.0 / 80.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(lin.A, physics(80.0)[0], rtol=1e-8)


def test_the_cli_writes_a_spec_from_it(msd3, tmp_path):
    res = run_cli("linearize", msd3, "--Ts", "0.01", "--out", tmp_path / "msd.toml")
    assert res.code == 0, res.err
    from gainlink.spec import load_spec

    spec = load_spec(tmp_path / "msd.toml")
    np.testing.assert_allclose(spec.plant.A, physics()[0], rtol=1e-8)
    assert spec.operating_point.y_op.tolist() == [S0]


MSD_TEMPLATE = """
[controller]
method = "lqr"
Q_diag = [100.0, 1.0]
R_diag = [0.01]

[integral]
outputs = ["s"]
Q_diag = [1000.0]

[observer]
method = "kalman"
form = "predictor"
W_diag = [1.0e-4, 1.0e-3]
V_diag = [1.0e-6]

[limits]
u_min = [-100.0]
u_max = [100.0]
anti_windup = "clamp"
"""


def test_a_sil_run_tracks_through_it_and_agrees_with_its_model(msd3, tmp_path):
    """linearize -> design -> SIL with the C loop: the only interface runs, the loop tracks, and the plant (a linear
    one integrated by CVode) is its model to within the solver's tolerance."""
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import parse_scenario
    from gainlink.shipping.artifact import load

    (tmp_path / "t.toml").write_text(MSD_TEMPLATE, "utf-8")
    res = run_cli("linearize", msd3, "--Ts", "0.01", "--out", tmp_path / "msd.toml", "--template", tmp_path / "t.toml")
    assert res.code == 0, res.err
    assert run_cli("design", tmp_path / "msd.toml", "--out", tmp_path).code == 0
    art = load(tmp_path / "gains.json")
    assert art.provenance["plant_interface"] == "me: the FMU has Model Exchange only"
    sc = {
        "name": "msd3",
        "artifact": str(tmp_path / "gains.json"),
        "duration": 4.0,
        "plant": {"kind": "fmu", "path": str(msd3)},
        "transport": {},
        "reference": {"r_s": {"kind": "step", "at": 0.5, "value": 0.6}},
    }
    r = run_scenario(parse_scenario(sc), artifact=art)
    assert r.complete and r.info["plant"]["interface"] == "me"
    assert r.metrics["outputs_final"]["s"] == pytest.approx(0.6, abs=1e-3)
    assert r.metrics["model_twin"]["worst"] < 1e-4 and not r.metrics["model_twin"]["warning"]
