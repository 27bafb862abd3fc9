"""``gainlink linearize`` on a Co-Simulation-only FMU: the project's Wood-Berry column (dead times as delay lines)
is identified from doStep pulse responses out of a saved FMU state, and must equal the exact zero-order-hold
discretisation of the Wood-Berry model with its dead times, derived independently here with python-control
(c2d of each first-order lag times z^-d for a dead time of d steps)."""

from __future__ import annotations

import re
import zipfile

import control as ct
import numpy as np
import pytest
from gainlink.errors import PlantError
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.hil.plants.build import build_fmu
from gainlink.hil.plants.linearize import linearize
from gainlink.spec import load_spec
from support.cli import assert_refused, run_cli
from support.hil import udp_transport
from support.paths import EXAMPLES

GAIN = np.array([[12.8, -18.9], [6.6, -19.4]])  # Wood & Berry (1973), minutes
TAU = np.array([[16.7, 21.0], [10.9, 14.4]])
DEAD = np.array([[1.0, 3.0], [7.0, 3.0]])


@pytest.fixture(scope="module")
def wood_berry():
    return build_fmu("wood_berry")


def _exact_markov(h: float, steps: int) -> np.ndarray:
    """Pulse responses y_k (k = 1..steps) of the exact ZOH model at step h, per channel from python-control."""
    out = np.zeros((steps, 2, 2))
    t = np.arange(steps + 1) * h
    for i in range(2):
        for j in range(2):
            lag = ct.c2d(ct.tf([GAIN[i, j]], [TAU[i, j], 1.0]), h, method="zoh")
            d = int(round(DEAD[i, j] / h))
            delay = ct.tf([1.0], [1.0] + [0.0] * d, h)  # z^-d
            pulse = np.zeros(t.size)
            pulse[0] = 1.0  # a unit input held over the first step
            out[:, i, j] = ct.forced_response(lag * delay, T=t, U=pulse).outputs[1:]
    return out


def _markov(A, B, C, steps):
    out, x = [], B.copy()
    for _ in range(steps):
        out.append(C @ x)
        x = A @ x
    return np.array(out)


def _hankel_rank(h: np.ndarray) -> int:
    half = h.shape[0] // 2
    H = np.block([[h[i + j] for j in range(half)] for i in range(half)])
    s = np.linalg.svd(H, compute_uv=False)
    return int(np.sum(s > 1e-9 * s[0]))


@pytest.mark.parametrize("h", [1.0, 0.5])
def test_identified_model_equals_the_exact_zoh_model_with_dead_times(wood_berry, h):
    lin = linearize(wood_berry, Ts=h)
    assert lin.Ts == h and lin.inputs == ("reflux", "steam") and lin.outputs == ("x_D", "x_B")
    exact = _exact_markov(h, 400)
    # Minimal order: the exact model's Hankel rank; by hand, 4 lags + one delay line per input as long as its
    # longest dead time (reflux 7 min, steam 3 min): 4 + 10 / h.
    assert _hankel_rank(exact) == 4 + int(round(10 / h)) == lin.A.shape[0]
    # Equal Markov parameters (far beyond the 100 identified steps) make two minimal realisations similar.
    ident = _markov(lin.A, lin.B, lin.C, 400)
    np.testing.assert_allclose(ident, exact, rtol=0, atol=1e-10 * np.abs(exact).max())
    np.testing.assert_array_equal(lin.D, np.zeros((2, 2)))
    poles = np.sort(np.abs(np.linalg.eigvals(lin.A)))[::-1]
    np.testing.assert_allclose(poles[:4], np.sort(np.exp(-h / TAU.ravel()))[::-1], rtol=0, atol=1e-9)
    # The delay lines are a nilpotent block, whose eigenvalues at 0 rounding scatters (to ~0.06 for a chain of 14):
    # check the minimal polynomial instead, z^L (z - a11)(z - a12)(z - a21)(z - a22), L the longest dead time in steps.
    P = np.linalg.matrix_power(lin.A, int(round(7 / h)))
    for a in np.exp(-h / TAU.ravel()):
        P = P @ (lin.A - a * np.eye(lin.A.shape[0]))
    assert np.abs(P).max() < 1e-10


def test_cli_spec_from_the_cosimulation_fmu_designs_and_tracks_in_hil(wood_berry, tmp_path):
    spec = tmp_path / "wb.toml"
    res = run_cli("linearize", "wood_berry", "--Ts", "1", "--out", spec, "--template", EXAMPLES / "wood_berry.toml")
    assert res.code == 0, res.err
    assert "n=14 m=2 p=2" in res.out and "ERA order 14" in res.out
    s = load_spec(spec)
    assert s.plant.kind == "discrete" and s.Ts == 1.0
    res = run_cli("design", spec, "--out", tmp_path)
    assert res.code == 0, res.err
    # The design on the identified model (exact dead times, no Pade approximants) runs against the FMU itself.
    r = run_scenario(
        parse_scenario(
            {
                "artifact": str(tmp_path / "gains.json"),
                "duration": 150.0,
                "controller": "reference",
                "step_timeout": 2.0,
                "transport": udp_transport(),
                "plant": {"kind": "fmu", "fmu": "wood_berry"},
                "reference": {"r_x_D": {"kind": "step", "at": 5.0, "value": 1.0}},
            }
        )
    )
    m = r.metrics
    assert r.complete and m["steps"] == 150 and m["lost"] == 0
    assert m["outputs_final"]["x_D"] == pytest.approx(1.0, abs=0.02)
    assert m["outputs_final"]["x_B"] == pytest.approx(0.0, abs=0.02)
    assert m["tracked"]["r_x_D"]["settling_time_s"] is not None


def test_cosimulation_fmu_that_cannot_save_its_state_is_refused_in_one_line(wood_berry, tmp_path):
    frozen = tmp_path / "no_state.fmu"
    with zipfile.ZipFile(wood_berry) as src, zipfile.ZipFile(frozen, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = re.sub(
                    rb'canGetAndSetFMUstate="true" canSerializeFMUstate="true"',
                    b'canGetAndSetFMUstate="false" canSerializeFMUstate="false"',
                    data,
                )
            dst.writestr(item, data)
    for argv, message in [
        ((frozen, "--Ts", "1"), "cannot save its state (canGetAndSetFMUstate=false)"),
        ((wood_berry, "--Ts", "1", "--method", "directional"), "Co-Simulation only: no directional derivatives"),
        ((wood_berry, "--Ts", "0.3"), "does not divide the dead time"),
        ((wood_berry, "--Ts", "1", "--horizon", "2"), "--horizon must be a whole number of steps, at least 4"),
        ((wood_berry, "--Ts", "1", "--horizon", "8"), "the horizon of 8 steps is too short"),
    ]:
        assert_refused(("linearize", *argv, "--out", tmp_path / "x.toml"), message, tmp_path)


def test_nonlinear_cosimulation_fmu_identifies_to_the_sampled_jacobian_at_an_equilibrium(cart_fmu, tmp_path):
    # The project's cart-pendulum FMU with its Model Exchange interface removed: identified at the unstable
    # upright equilibrium, it must equal the ZOH sampling (python-control c2d) of the Jacobian its Model Exchange
    # interface gives; the CS FMU integrates with RK4 inside doStep, so the match is to ~1e-10, not to rounding.
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
    me = linearize(cart_fmu, outputs=["x", "theta"])
    sampled = ct.c2d(ct.ss(me.A, me.B, me.C, me.D), 0.01, method="zoh")
    cs = linearize(cs_only, Ts=0.01, outputs=["x", "theta"])
    assert cs.A.shape == (4, 4)
    expected = _markov(sampled.A, sampled.B, sampled.C, 200)
    np.testing.assert_allclose(_markov(cs.A, cs.B, cs.C, 200), expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    # Away from an equilibrium the pendulum falls: the pulse responses are not those of one linear time-invariant
    # model, and linearize says so instead of writing a wrong spec.
    with pytest.raises(PlantError, match="not linear/time-invariant about this point"):
        linearize(cs_only, Ts=0.01, outputs=["x", "theta"], at={"theta": 0.2})
