"""Plant kinds of the bridge beyond the project's own models: ``linear`` from any spec or artifact with
parameter perturbation, and ``python`` plants named as ``module:Class`` or found through the entry-point
group ``gainlink.plants`` (a real distribution's metadata on ``sys.path``, as pip lays it out)."""

from __future__ import annotations

import textwrap

import control as ct
import numpy as np
import pytest
from gainlink.errors import PlantError
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.hil.plants.config import plant_from_config
from gainlink.hil.plants.linear import model_from_spec, perturb_model
from gainlink.shipping.artifact import load
from support.hil import udp_transport
from support.paths import EXAMPLES

PENDULUM = EXAMPLES / "pendulum.toml"
# The pendulum spec's matrices, written out here as the oracle (examples/pendulum.toml's header derives them).
A_PEND = np.array([[0, 1, 0, 0], [0, 0, -0.981, 0], [0, 0, 0, 1], [0, 0, 21.582, 0]], float)
B_PEND = np.array([[0.0], [1.0], [0.0], [-2.0]])
C_PEND = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])


def _simulate(plant, u, dt):
    plant.reset(initial={"theta": 0.05})
    ys = [plant.outputs()]
    for uk in u:
        plant.advance(u=np.array([uk]), dt=dt)
        ys.append(plant.outputs())
    return np.array(ys)


def _oracle(A, B, u, dt):
    sys = ct.c2d(ct.ss(A, B, C_PEND, np.zeros((2, 1))), dt, method="zoh")
    res = ct.forced_response(sys, U=np.append(u, 0.0), X0=[0, 0, 0.05, 0])
    return res.outputs.T


def test_linear_plant_from_a_spec_with_perturbed_entries_and_scaled_matrix():
    u = np.sin(np.arange(200) * 0.05)
    config = {
        "kind": "linear",
        "spec": str(PENDULUM),
        "perturb": {"A[3][2]": 0.1, "A[1][2]": -0.2},
        "scale": {"B": 1.5},
    }
    plant = plant_from_config(config)
    A = A_PEND.copy()
    A[3, 2] *= 1.1
    A[1, 2] *= 0.8
    np.testing.assert_allclose(_simulate(plant, u, 0.01), _oracle(A, 1.5 * B_PEND, u, 0.01), rtol=1e-9, atol=1e-12)
    nominal = plant_from_config({"kind": "linear", "spec": str(PENDULUM)})
    np.testing.assert_allclose(_simulate(nominal, u, 0.01), _oracle(A_PEND, B_PEND, u, 0.01), rtol=1e-9, atol=1e-12)
    # The hook is a pure function: the nominal model is untouched.
    model = model_from_spec(PENDULUM)
    perturb_model(model, perturb={"A[3][2]": 0.1})
    assert model.A[3, 2] == 21.582


def test_linear_plant_defaults_to_the_scenario_artifact_and_reads_another_one(example_artifacts, tmp_path):
    art = load(example_artifacts["pendulum"])
    u = np.cos(np.arange(50) * 0.1)
    from_scenario = _simulate(plant_from_config({"kind": "linear"}, artifact=art), u, 0.01)
    named = plant_from_config(
        {"kind": "linear", "artifact": example_artifacts["pendulum"].name},
        base_dir=example_artifacts["pendulum"].parent,
    )
    np.testing.assert_array_equal(_simulate(named, u, 0.01), from_scenario)
    np.testing.assert_allclose(from_scenario, _oracle(A_PEND, B_PEND, u, 0.01), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    "config, message",
    [
        ({"perturb": {"E[0][0]": 0.1}}, 'not of the form "A[i][j]"'),
        ({"perturb": {"A[4][0]": 0.1}}, "A[4][0] is outside A (4x4"),
        ({"perturb": {"A[0][1]": float("nan")}}, "must be a finite number"),
        ({"perturb": {"A[0][1]": "big"}}, "must be a finite number"),
        ({"scale": {"Q": 2.0}}, "scale names matrix 'Q'"),
        ({"artifact": "gains.json"}, "give spec or artifact, not both"),
        ({"colour": "red"}, "unknown key(s) colour"),
    ],
)
def test_linear_plant_refuses_bad_perturbations_in_one_line(config, message):
    with pytest.raises(PlantError) as err:
        plant_from_config({"kind": "linear", "spec": str(PENDULUM), **config})
    assert message in str(err.value) and "\n" not in str(err.value)


def test_linear_plant_without_a_model_or_with_a_missing_spec_says_so(tmp_path):
    with pytest.raises(PlantError, match="needs a model"):
        plant_from_config({"kind": "linear"})
    with pytest.raises(PlantError, match=r"plant linear: .*nope\.toml"):
        plant_from_config({"kind": "linear", "spec": "nope.toml"}, base_dir=tmp_path)


def test_hil_run_against_a_perturbed_linear_plant_tracks_and_differs_from_nominal(example_artifacts):
    base = {
        "artifact": str(example_artifacts["pendulum"]),
        "duration": 8.0,
        "controller": "reference",
        "step_timeout": 2.0,
        "transport": udp_transport(),
        "reference": {"r_x": {"kind": "step", "at": 0.5, "value": 0.2}},
    }
    nominal = run_scenario(parse_scenario({**base, "plant": {"kind": "linear", "spec": str(PENDULUM)}}))
    heavy = run_scenario(
        parse_scenario({**base, "plant": {"kind": "linear", "spec": str(PENDULUM), "scale": {"B": 0.7}}})
    )
    for r in (nominal, heavy):
        assert r.complete and r.metrics["steps"] == 800
        assert r.metrics["outputs_final"]["x"] == pytest.approx(0.2, abs=0.01)
    # A 30 % weaker actuator needs a larger command for the same cart position.
    assert np.max(np.abs(heavy.trace.u)) > 1.2 * np.max(np.abs(nominal.trace.u))


# A user's plant: the pendulum's linear model with a mass option, deriving from the project's base class.
USER_MODULE = textwrap.dedent('''
    import numpy as np
    from scipy.linalg import expm
    from gainlink.hil.plants.base import Plant

    class Cart(Plant):
        """A point mass on a line pushed by force F: x'' = F / mass."""

        def __init__(self, *, mass=1.0):
            if not mass > 0:
                raise ValueError("mass must be positive")
            self.name, self.mass = "cart", float(mass)
            self.input_names, self.output_names, self.state_names = ("F",), ("x",), ("x", "v")
            self.x = np.zeros(2)

        def reset(self, *, initial):
            self.x = np.array([initial.get("x", 0.0), initial.get("v", 0.0)])

        def outputs(self):
            return self.x[:1].copy()

        def advance(self, *, u, dt):
            v = self.x[1] + dt * u[0] / self.mass
            self.x = np.array([self.x[0] + dt * self.x[1] + 0.5 * dt * dt * u[0] / self.mass, v])

        def state(self):
            return self.x.copy()

        def save_state(self):
            return self.x.copy()

        def restore_state(self, snapshot):
            self.x = snapshot.copy()

    class NotAPlant:
        pass
''')


@pytest.fixture
def user_package(tmp_path, monkeypatch):
    """A module and an installed distribution's metadata registering it in ``gainlink.plants`` (the layout pip
    writes into site-packages: ``<name>.dist-info/METADATA`` and ``entry_points.txt``), on ``sys.path``."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "gl_user_plants.py").write_text(USER_MODULE, "utf-8")
    info = site / "gl_user_plants-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: gl-user-plants\nVersion: 1.0\n", "utf-8")
    (info / "entry_points.txt").write_text(
        "[gainlink.plants]\nuser_cart = gl_user_plants:Cart\nbroken = gl_user_plants:NotAPlant\n"
        "gone = gl_user_plants_missing:Cart\n",
        "utf-8",
    )
    monkeypatch.syspath_prepend(str(site))
    return site


def _double_integrator(u, dt, mass):
    sys = ct.c2d(ct.ss([[0, 1], [0, 0]], [[0], [1 / mass]], [[1, 0]], [[0]]), dt, method="zoh")
    return ct.forced_response(sys, U=np.append(u, 0.0), X0=[0.0, 0.0]).outputs


@pytest.mark.parametrize(
    "config", [{"kind": "python", "class": "gl_user_plants:Cart", "mass": 2.0}, {"kind": "user_cart", "mass": 2.0}]
)
def test_user_python_plant_by_class_or_entry_point_gets_its_config(user_package, config):
    plant = plant_from_config(config)
    assert type(plant).__module__ == "gl_user_plants" and plant.mass == 2.0
    u = np.sin(np.arange(100) * 0.2)
    plant.reset(initial={})
    ys = [plant.outputs()[0]]
    for uk in u:
        plant.advance(u=np.array([uk]), dt=0.1)
        ys.append(plant.outputs()[0])
    np.testing.assert_allclose(ys, _double_integrator(u, 0.1, 2.0), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize(
    "config, message",
    [
        ({"kind": "python", "class": "gl_no_such_module:Cart"}, "cannot import module 'gl_no_such_module'"),
        ({"kind": "python", "class": "gl_user_plants:Bus"}, "module 'gl_user_plants' has no class 'Bus'"),
        ({"kind": "python", "class": "gl_user_plants:NotAPlant"}, "is not a Plant class"),
        ({"kind": "python", "class": "gl_user_plants"}, 'must be of the form "module:Class"'),
        ({"kind": "python"}, 'give class = "module:Class"'),
        ({"kind": "python", "class": "gl_user_plants:Cart", "mass": -1.0}, "Cart(mass) failed: mass must be positive"),
        ({"kind": "python", "class": "gl_user_plants:Cart", "colour": "red"}, "Cart(colour) failed"),
        ({"kind": "broken"}, "entry point gl_user_plants:NotAPlant): it is not a Plant class"),
        ({"kind": "gone"}, "cannot load it"),
        ({"kind": "no_such_plant"}, "unknown plant kind 'no_such_plant' (known: "),
    ],
)
def test_python_plant_errors_are_one_line(user_package, config, message):
    with pytest.raises(PlantError) as err:
        plant_from_config(config)
    assert message in str(err.value) and "\n" not in str(err.value)
    if config["kind"] == "no_such_plant":  # the installed plugins are listed with the built-in kinds
        assert "user_cart" in str(err.value) and "linear" in str(err.value)
