"""Plant FMUs built from the project's C sources with fmpy, the built-in models, and linearisation.

Expected values are independent of the code under test: the linearisation about upright is the
closed form from the issue (M=1, m=0.1, l=0.5, g=9.81), the examples' matrices are read from
examples/*.toml, and the FMU is compared with the Python model it must agree with.
"""

from __future__ import annotations

import tomllib
import zipfile

import numpy as np
import pytest
from gainlink.errors import PlantError
from gainlink.hil.plants.config import plant_from_config
from gainlink.hil.plants.fmu import FmuPlant
from gainlink.hil.plants.linearize import linearize
from gainlink.hil.plants.models import CartPendulum, QuadrotorLateral, WoodBerry
from support.cli import assert_refused, run_cli
from support.paths import EXAMPLES

M, m, l, g = 1.0, 0.1, 0.5, 9.81
A_UP = np.array([[0, 1, 0, 0], [0, 0, -m * g / M, 0], [0, 0, 0, 1], [0, 0, (M + m) * g / (M * l), 0]])
B_UP = np.array([[0], [1 / M], [0], [-1 / (M * l)]])


def test_fmu_builds_and_passes_fmpy_validation(cart_fmu):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(cart_fmu)) == []
    md = read_model_description(str(cart_fmu))
    assert md.coSimulation is not None and md.modelExchange is not None
    with zipfile.ZipFile(cart_fmu) as zf:
        assert "binaries/linux64/cart_pendulum.so" in zf.namelist()


def test_fmu_matches_python_model_and_restores_its_state(cart_fmu):
    fmu = FmuPlant(path=cart_fmu)
    py = CartPendulum(step=1e-3)
    try:
        assert fmu.input_names == ("F",) and fmu.output_names == ("x", "theta")
        assert fmu.state_names == ("x", "x_dot", "theta", "theta_dot")
        rng = np.random.default_rng(3)
        for plant in (fmu, py):
            plant.reset(initial={"theta": 0.1, "x_dot": -0.2})
        for k in range(300):
            u = rng.normal(scale=2.0, size=1)
            fmu.advance(u=u, dt=0.01)
            py.advance(u=u, dt=0.01)
            if k == 150:
                snap = fmu.save_state()
                ahead = [(fmu.advance(u=np.array([5.0]), dt=0.01), fmu.outputs())[1] for _ in range(3)]
                fmu.restore_state(snap)
                again = [(fmu.advance(u=np.array([5.0]), dt=0.01), fmu.outputs())[1] for _ in range(3)]
                assert np.array_equal(np.array(ahead), np.array(again))
                fmu.restore_state(snap)
        np.testing.assert_allclose(fmu.state(), py.state(), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(fmu.outputs(), py.outputs(), rtol=1e-9, atol=1e-12)
    finally:
        fmu.close()


@pytest.mark.parametrize("method", ["directional", "differences"])
def test_linearization_about_upright_equals_the_closed_form(cart_fmu, method):
    lin = linearize(cart_fmu, at={"theta": 0.0}, method=method)
    tol = 1e-12 if method == "directional" else 1e-7
    np.testing.assert_allclose(lin.A, A_UP, atol=tol)
    np.testing.assert_allclose(lin.B, B_UP, atol=tol)
    np.testing.assert_allclose(lin.C, [[1, 0, 0, 0], [0, 0, 1, 0]], atol=tol)
    np.testing.assert_allclose(lin.D, 0.0, atol=tol)
    assert lin.method.startswith("directional" if method == "directional" else "central")


def test_linearization_away_from_upright_agrees_between_methods(cart_fmu):
    at = {"theta": 0.3, "theta_dot": 0.5, "F": 1.5}
    dd = linearize(cart_fmu, at=at, method="directional")
    cd = linearize(cart_fmu, at=at, method="differences")
    for a, b in ((dd.A, cd.A), (dd.B, cd.B)):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)
    assert abs(dd.A[3, 2] - A_UP[3, 2]) > 0.1 and abs(dd.A[1, 3]) > 0.01  # really a different operating point


def test_linearize_cli_spec_designs_like_the_example(cart_fmu, tmp_path, example_artifacts):
    import json

    spec = tmp_path / "from_fmu.toml"
    res = run_cli(
        "linearize",
        cart_fmu,
        "--at",
        "theta=0",
        "--out",
        spec,
        "--name",
        "pendulum",
        "--template",
        EXAMPLES / "pendulum.toml",
    )
    assert res.code == 0, res.err
    data = tomllib.loads(spec.read_text())
    np.testing.assert_allclose(data["plant"]["A"], A_UP, atol=1e-12)
    out = tmp_path / "design"
    assert run_cli("design", spec, "--out", out).code == 0
    mine = json.loads((out / "gains.json").read_text())
    example = json.loads(example_artifacts["pendulum"].read_text())
    for key in ("K", "Ki", "L"):
        np.testing.assert_allclose(mine[key], example[key], rtol=1e-6, atol=1e-9)
    # Without a template the spec still designs (neutral weights), so FMU -> firmware needs no matrices typed.
    bare = tmp_path / "bare.toml"
    assert run_cli("linearize", cart_fmu, "--out", bare).code == 0
    assert run_cli("design", bare, "--out", tmp_path / "bare").code == 0


def _numeric_jacobian(plant, n_in):
    x0, u0 = np.zeros(len(plant.state_names)), np.zeros(n_in)
    h = 1e-6
    A = np.column_stack(
        [(plant.derivatives(x0 + h * e, u0) - plant.derivatives(x0 - h * e, u0)) / (2 * h) for e in np.eye(len(x0))]
    )
    B = np.column_stack(
        [(plant.derivatives(x0, u0 + h * e) - plant.derivatives(x0, u0 - h * e)) / (2 * h) for e in np.eye(n_in)]
    )
    return A, B


@pytest.mark.parametrize("name, cls", [("pendulum", CartPendulum), ("quadrotor_lateral", QuadrotorLateral)])
def test_builtin_models_linearise_to_the_example_specs(name, cls):
    spec = tomllib.loads((EXAMPLES / f"{name}.toml").read_text())
    plant = cls()
    assert list(plant.state_names) == spec["plant"]["states"]
    assert list(plant.output_names) == spec["plant"]["outputs"]
    A, B = _numeric_jacobian(plant, 1)
    np.testing.assert_allclose(A, spec["plant"]["A"], atol=1e-6)
    np.testing.assert_allclose(B, spec["plant"]["B"], atol=1e-6)


def test_wood_berry_has_its_gains_and_dead_times():
    wb = WoodBerry(step=0.1)
    wb.reset(initial={})
    t, xd, xb = [], [], []
    for k in range(2000):  # unit step on reflux, 200 min
        wb.advance(u=np.array([1.0, 0.0]), dt=0.1)
        t.append((k + 1) * 0.1)
        y = wb.outputs()
        xd.append(y[0])
        xb.append(y[1])
    t, xd, xb = np.array(t), np.array(xd), np.array(xb)
    assert np.all(xd[t <= 1.0 + 1e-9] == 0.0) and xd[t > 1.05][0] > 0  # 1 min dead time
    assert np.all(xb[t <= 7.0 + 1e-9] == 0.0) and xb[t > 7.05][0] > 0  # 7 min dead time
    assert xd[-1] == pytest.approx(12.8, rel=1e-3) and xb[-1] == pytest.approx(6.6, rel=1e-3)
    # First-order lag: 63.2 % of the gain one time constant after the dead time.
    assert np.interp(1.0 + 16.7, t, xd) == pytest.approx(12.8 * (1 - np.exp(-1)), rel=1e-2)


def test_model_exchange_only_fmu_runs_through_fmpys_solver_like_cosimulation(cart_fmu, tmp_path):
    me_only = tmp_path / "me_only.fmu"
    with zipfile.ZipFile(cart_fmu) as src, zipfile.ZipFile(me_only, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                start = text.index("<CoSimulation")
                end = text.index("</CoSimulation>") + len("</CoSimulation>")
                data = (text[:start] + text[end:]).encode()
            dst.writestr(item, data)
    with pytest.raises(PlantError, match="no Co-Simulation interface"):
        plant_from_config({"kind": "fmu", "path": str(me_only), "interface": "cs"})
    me = plant_from_config({"kind": "fmu", "path": str(me_only), "outputs": ["x", "theta"]})
    cs = plant_from_config({"kind": "fmu", "path": str(cart_fmu), "outputs": ["x", "theta"], "interface": "cs"})
    model = CartPendulum(outputs=["x", "theta"], step=1e-4)
    try:
        assert type(me).__name__ == "FmuModelExchangePlant"
        for plant in (me, cs, model):
            plant.reset(initial={"theta": 0.1})
        for k in range(100):
            u = np.array([np.sin(0.1 * k)])
            for plant in (me, cs, model):
                plant.advance(u=u, dt=0.01)
        # CVode (rtol 1e-8) and fine RK4 agree on the nonlinear pendulum as it falls over (theta ~2.7 rad after
        # 1 s, where the fall amplifies any difference); state snapshots restore the ME FMU.
        np.testing.assert_allclose(me.state(), model.state(), rtol=1e-4, atol=1e-6)
        snap = me.save_state()
        y_before = me.outputs()
        me.advance(u=np.array([5.0]), dt=0.1)
        me.restore_state(snap)
        np.testing.assert_array_equal(me.outputs(), y_before)
        me.advance(u=np.array([0.0]), dt=0.01)
        model.advance(u=np.array([0.0]), dt=0.01)
        np.testing.assert_allclose(me.state(), model.state(), rtol=1e-4, atol=1e-6)
    finally:
        me.close()
        cs.close()
    lin = linearize(me_only, at={})  # Model Exchange is all linearize needs
    assert lin.A.shape == (4, 4)


def test_missing_and_broken_fmus_are_refused(tmp_path, cart_fmu):
    with pytest.raises(PlantError, match="not found"):
        plant_from_config({"kind": "fmu", "path": str(tmp_path / "nope.fmu")})
    junk = tmp_path / "junk.fmu"
    junk.write_bytes(b"this is not a zip archive")
    with pytest.raises(PlantError, match="not a zip archive"):
        plant_from_config({"kind": "fmu", "path": str(junk)})
    no_binary = tmp_path / "no_binary.fmu"
    with zipfile.ZipFile(cart_fmu) as src, zipfile.ZipFile(no_binary, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    with pytest.raises(PlantError, match="cannot load its binary"):
        plant_from_config({"kind": "fmu", "path": str(no_binary)})
    with pytest.raises(PlantError, match="unknown key"):
        plant_from_config({"kind": "fmu", "path": str(cart_fmu), "colour": "red"})
    with pytest.raises(PlantError, match=r"no variable named .phi. \(for outputs\)"):
        plant_from_config({"kind": "fmu", "path": str(cart_fmu), "outputs": ["x", "phi"]})


def test_quadrotor_fmu_matches_its_model_and_the_example():
    from fmpy.validation import validate_fmu
    from gainlink.hil.plants.build import build_fmu

    path = build_fmu("quadrotor_lateral")
    assert validate_fmu(str(path)) == []
    spec = tomllib.loads((EXAMPLES / "quadrotor_lateral.toml").read_text())
    lin = linearize(path, at={})
    assert list(lin.states) == spec["plant"]["states"] and list(lin.outputs) == spec["plant"]["outputs"]
    np.testing.assert_allclose(lin.A, spec["plant"]["A"], atol=1e-12)
    np.testing.assert_allclose(lin.B, spec["plant"]["B"], atol=1e-12)
    fmu, py = FmuPlant(path=path), QuadrotorLateral(step=1e-3)
    try:
        for plant in (fmu, py):
            plant.reset(initial={"phi": 0.05, "y": 0.3})
        u = np.array([0.01])
        for _ in range(200):
            fmu.advance(u=-u, dt=0.005)
            py.advance(u=-u, dt=0.005)
        np.testing.assert_allclose(fmu.state(), py.state(), rtol=1e-9, atol=1e-12)
    finally:
        fmu.close()


def test_fmi3_cosimulation_fmu_runs_like_the_fmi2_one(tmp_path, example_artifacts):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    from gainlink.hil.loop.bridge import run_scenario
    from gainlink.hil.loop.scenario import parse_scenario
    from gainlink.hil.plants.build import build_fmu
    from support.hil import udp_transport

    path = build_fmu("cart_pendulum3")
    assert validate_fmu(str(path)) == []
    assert read_model_description(str(path)).fmiVersion == "3.0"
    fmu3 = FmuPlant(path=path, states=["x", "x_dot", "theta", "theta_dot"])
    py = CartPendulum(step=1e-3)
    try:
        for plant in (fmu3, py):
            plant.reset(initial={"theta": 0.1})
        for _ in range(200):
            fmu3.advance(u=np.array([0.4]), dt=0.01)
            py.advance(u=np.array([0.4]), dt=0.01)
        np.testing.assert_allclose(fmu3.state(), py.state(), rtol=1e-9, atol=1e-12)
        snap = fmu3.save_state()
        fmu3.advance(u=np.array([1.0]), dt=0.01)
        ahead = fmu3.outputs()
        fmu3.restore_state(snap)
        fmu3.advance(u=np.array([1.0]), dt=0.01)
        assert np.array_equal(ahead, fmu3.outputs())
    finally:
        fmu3.close()
    # The same lockstep HIL run (Python reference node as controller) on the FMI 2.0 and 3.0 FMUs agrees.
    finals = []
    for name in ("cart_pendulum", "cart_pendulum3"):
        r = run_scenario(
            parse_scenario(
                {
                    "artifact": str(example_artifacts["pendulum"]),
                    "duration": 1.0,
                    "controller": "reference",
                    "plant": {"kind": "fmu", "fmu": name},
                    "transport": udp_transport(),
                    "initial_state": {"theta": 0.1},
                }
            )
        )
        assert r.complete
        finals.append(r.trace.y)
    np.testing.assert_allclose(finals[0], finals[1], rtol=1e-9, atol=1e-12)


def test_linearize_and_fmu_commands_refuse_bad_input_in_one_line(cart_fmu, tmp_path):
    cs_only = tmp_path / "cs_only.fmu"
    with zipfile.ZipFile(cart_fmu) as src, zipfile.ZipFile(cs_only, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                data = (
                    text[: text.index("<ModelExchange")]
                    + text[text.index("</ModelExchange>") + len("</ModelExchange>") :]
                ).encode()
            dst.writestr(item, data)
    out = tmp_path / "spec.toml"
    cases = [
        (("linearize", tmp_path / "none.fmu", "--out", out), "not found"),
        (("linearize", cart_fmu, "--at", "theta", "--out", out), "--at expects NAME=VALUE"),
        (("linearize", cart_fmu, "--at", "theta=abc", "--out", out), "is not a number"),
        (("linearize", cart_fmu, "--at", "psi=1", "--out", out), "no Real variable 'psi'"),
        (("linearize", cs_only, "--method", "directional", "--out", out), "Co-Simulation only: no directional"),
        (("linearize", cart_fmu, "--Ts", "0", "--out", out), "--Ts must be positive"),
        (("hil", "fmu", "no_such_plant"), "no project FMU named 'no_such_plant'"),
    ]
    for argv, needle in cases:
        assert_refused(argv, needle, tmp_path)


def test_linearize_refuses_a_value_outside_the_fmus_declared_range(cart_fmu, tmp_path):
    """The model description bounds the cart mass (min 1e-6 kg) and the multirotor's throttle (max 1): a
    negative mass, a throttle above full or a non-finite value is refused in one line naming the variable and
    its range, exit 2, nothing written (was: a spec linearised at M = -1). A value inside the range passes."""
    from gainlink.hil.plants.build import build_fmu

    multirotor = build_fmu("multirotor_vertical")
    out = tmp_path / "spec.toml"
    cases = [
        ((cart_fmu, "--at", "M=-1"), "M = -1 is outside the range the FMU declares for it (min 1e-06)"),
        ((cart_fmu, "--at", "l=0"), "l = 0 is outside the range"),
        ((cart_fmu, "--at", "theta=nan"), "theta = nan is not a finite number"),
        (
            (multirotor, "--at", "throttle=1.5"),
            "throttle = 1.5 is outside the range the FMU declares for it (min 0, max 1)",
        ),
        ((multirotor, "--at", "mass=-2", "--at", "z=2"), "mass = -2 is outside the range"),
    ]
    for args, needle in cases:
        assert_refused(("linearize", *args, "--Ts", "0.01", "--out", out), needle, tmp_path)
    assert run_cli("linearize", cart_fmu, "--at", "M=2", "--Ts", "0.01", "--out", out).code == 0


# ---- Wood-Berry column as a Co-Simulation FMU (dead times as delay lines) ----

WB_TS = tomllib.loads((EXAMPLES / "wood_berry.toml").read_text())["Ts"]


@pytest.fixture(scope="module")
def wood_berry_fmu():
    from gainlink.hil.plants.build import build_fmu

    return build_fmu("wood_berry")


def test_wood_berry_fmu_is_cosimulation_only_with_the_builtin_names(wood_berry_fmu):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(wood_berry_fmu)) == []
    md = read_model_description(str(wood_berry_fmu))
    assert md.coSimulation is not None and md.modelExchange is None
    assert md.coSimulation.canGetAndSetFMUstate and not md.coSimulation.canHandleVariableCommunicationStepSize
    spec = tomllib.loads((EXAMPLES / "wood_berry.toml").read_text())
    fmu = FmuPlant(path=wood_berry_fmu)
    try:
        assert fmu.input_names == WoodBerry.all_inputs == tuple(spec["plant"]["inputs"])
        assert fmu.output_names == WoodBerry.all_outputs == tuple(spec["plant"]["outputs"])
        assert fmu.state_names == WoodBerry().state_names
    finally:
        fmu.close()


def _wb_bound(dt: float, sub: float) -> float:
    """Rounding bound between two exact ZOH discretisations of the lags: per communication step the built-in
    model takes dt/sub sub-steps, each (like the FMU's one step) a few roundings (exp, 1 - a, two products, a
    sum: <= 5 eps relative) of quantities below max|K| |u|; errors decay by a = exp(-dt/tau) per step, so the
    accumulated difference is below that per-step amount over (1 - a_max)."""
    eps, gain = np.finfo(float).eps, np.abs(WoodBerry.GAIN).max()
    per_step = 5 * (round(dt / sub) + 1) * eps * gain
    return per_step / (1.0 - np.exp(-dt / WoodBerry.TAU.max()))


@pytest.mark.parametrize("dt", [WB_TS, 0.5])
@pytest.mark.parametrize("j, name", [(0, "reflux"), (1, "steam")])
def test_wood_berry_fmu_step_response_equals_the_builtin_model(wood_berry_fmu, dt, j, name):
    fmu, py = FmuPlant(path=wood_berry_fmu), WoodBerry(step=0.1)
    u = np.zeros(2)
    u[j] = 1.0
    try:
        for plant in (fmu, py):
            plant.reset(initial={})
        n = int(round(200.0 / dt))
        t = dt * np.arange(1, n + 1)
        y_fmu, y_py, s_fmu, s_py = [], [], [], []
        for _ in range(n):
            fmu.advance(u=u, dt=dt)
            py.advance(u=u, dt=dt)
            y_fmu.append(fmu.outputs())
            y_py.append(py.outputs())
            s_fmu.append(fmu.state())
            s_py.append(py.state())
        y_fmu = np.array(y_fmu)
        tol = _wb_bound(dt, 0.1)
        assert tol < 1e-11
        np.testing.assert_allclose(y_fmu, np.array(y_py), rtol=0, atol=tol)
        np.testing.assert_allclose(np.array(s_fmu), np.array(s_py), rtol=0, atol=tol)
        # Nothing moves before the dead time (exactly zero), then the lag responds.
        for i in range(2):
            theta = WoodBerry.DELAY[i, j]
            assert np.all(y_fmu[t <= theta + 1e-9, i] == 0.0), (name, i)
            assert y_fmu[t > theta + 1e-9, i][0] * np.sign(WoodBerry.GAIN[i, j]) > 0
        np.testing.assert_allclose(y_fmu[-1], WoodBerry.GAIN[:, j], rtol=2e-3)  # 200 min >> every tau
    finally:
        fmu.close()


def test_wood_berry_fmu_state_restores_the_delay_lines(wood_berry_fmu):
    fmu = FmuPlant(path=wood_berry_fmu)
    rng = np.random.default_rng(7)

    def run(inputs):
        out = []
        for u in inputs:
            fmu.advance(u=np.asarray(u, float), dt=WB_TS)
            out.append(fmu.outputs())
        return np.array(out)

    try:
        a = np.tile([1.0, 0.5], (10, 1))
        run(rng.normal(size=(20, 2)))  # a history whose last 7 min still have to reach the outputs
        snap = fmu.save_state()
        ahead = run(a)
        # Another history overwrites every delay-line sample the snapshot depends on; restoring must bring
        # the old ones back, not only the lags.
        fmu.reset(initial={})
        run(rng.normal(size=(1100, 2)))
        fmu.restore_state(snap)
        assert np.array_equal(run(a), ahead)
        # A different reflux after the restore: x_D moves only after its 1 min dead time, x_B after 7 min;
        # steam was kept, so nothing else changes earlier.
        fmu.restore_state(snap)
        b = a.copy()
        b[:, 0] = -1.0
        other = run(b)
        steps_before = {0: int(WoodBerry.DELAY[0, 0] / WB_TS), 1: int(WoodBerry.DELAY[1, 0] / WB_TS)}
        for i, d in steps_before.items():
            assert np.array_equal(other[:d, i], ahead[:d, i]), i
            assert np.all(other[d:, i] != ahead[d:, i]), i
    finally:
        fmu.close()


def test_wood_berry_fmu_refuses_a_step_that_does_not_divide_a_dead_time(wood_berry_fmu, capfd):
    plant = plant_from_config({"kind": "fmu", "fmu": "wood_berry"})
    try:
        with pytest.raises(PlantError) as err:
            plant.advance(u=np.zeros(2), dt=0.4)
        msg = str(err.value)
        assert "\n" not in msg
        assert "communication step 0.4 min does not divide the dead time theta11 = 1 min" in msg
        assert plant.outputs().tolist() == [0.0, 0.0]
        # The refused step changed nothing: a dividing step still runs, and then the step length is fixed.
        plant.advance(u=np.array([1.0, 0.0]), dt=WB_TS)
        with pytest.raises(PlantError, match=r"communication step 0\.5 min differs from the first one"):
            plant.advance(u=np.zeros(2), dt=0.5)
        # A dead time longer than the delay line holds is refused the same way.
        plant.reset(initial={})
        with pytest.raises(PlantError, match=r"theta21 = 7 min is 7000 communication steps .* hold 1024"):
            plant.advance(u=np.zeros(2), dt=0.001)
    finally:
        plant.close()
    assert "[ERROR]" not in capfd.readouterr().out  # reported through the PlantError, not printed by fmpy
