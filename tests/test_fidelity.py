"""Design-time checks: compensator stability, float32 fidelity in closed loop, and realisations.

Oracles: the real host build closing the same loop (the design-time float32 number must be what the C
does), compensator poles from probing the float64 law (tests/test_onestep.py), numpy's eigenvectors for
the observer's conditioning, and a transformation recomputed here from the recorded design matrices.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.engines.native import NativeLoop
from gainlink.laws import design as design_spec
from gainlink.laws.lq.fidelity import THRESHOLD, float32_fidelity
from gainlink.proof.onestep import one_step_check
from gainlink.proof.reference import ReferenceLoop, StepResult
from gainlink.proof.simulation import simulate_linear
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import parse_spec
from support.cli import assert_refused, run_cli
from support.oracles import jacobian_poles
from support.paths import EXAMPLES


class CLoop:
    """The host build behind the ReferenceLoop interface, to close a loop with the real C."""

    def __init__(self, artifact):
        self.native = NativeLoop(artifact)

    def step(self, y, r=None) -> StepResult:
        out = self.native.step(y, r)
        m = out.u.size
        return StepResult(
            u=out.u.astype(float), saturated=((out.sat_mask >> np.arange(m)) & 1).astype(bool), fault=out.status == -2
        )


def flexible_spec(realization: str = "as_designed") -> dict:
    """A lightly damped flexible structure sampled fast: a 1 kg body carrying a 10 g appendage on a stiff
    spring (1e5 N/m, 0.2 N s/m: a 3178 rad/s mode, damping 0.3 %) plus its rigid-body motion, force on
    the body, both positions measured, sampled at 5 kHz (10x the mode), LQI on the body's position."""
    k, c, m1, m2 = 1e5, 0.2, 1.0, 0.01
    A = [[0, 0, 1, 0], [0, 0, 0, 1], [-k / m1, k / m1, -c / m1, c / m1], [k / m2, -k / m2, c / m2, -c / m2]]
    return {
        "name": "flexible",
        "Ts": 2e-4,
        "plant": {
            "kind": "continuous",
            "A": A,
            "B": [[0.0], [0.0], [1.0 / m1], [0.0]],
            "C": [[1.0, 0, 0, 0], [0, 1.0, 0, 0]],
            "states": ["x1", "x2", "v1", "v2"],
            "outputs": ["x1", "x2"],
            "inputs": ["F"],
        },
        "controller": {"method": "lqr", "Q_diag": [1.0] * 4, "R_diag": [1e-4]},
        "integral": {"outputs": ["x1"], "Q_diag": [100.0]},
        "observer": {"method": "kalman", "G": "B", "W": [[1.0]], "V_diag": [1e-6, 1e-6]},
        "limits": {"u_min": [-100.0], "u_max": [100.0]},
        "implementation": {"realization": realization},
    }


@pytest.fixture(scope="module")
def flexible():
    """name -> (DesignResult, Artifact) for the three realisations."""
    out = {}
    for kind in ("as_designed", "balanced", "schur"):
        result = design_spec(parse_spec(flexible_spec(kind)))
        out[kind] = (result, artifact_mod.from_dict(result.artifact))
    return out


def test_examples_record_a_stable_compensator_and_float32_within_threshold(example_artifacts):
    for name, path in example_artifacts.items():
        a = artifact_mod.load(path)
        comp, f32 = a.data["checks"]["compensator"], a.data["checks"]["float32"]
        assert comp["stable"] and comp["unstable_poles"] == []
        assert comp["spectral_radius"] == pytest.approx(np.max(np.abs(jacobian_poles(a))), rel=1e-9)
        assert f32["max_rel_u"] < THRESHOLD and f32["saturated_fraction"] > 0, name
        print(
            f"{name}: float32 closed-loop deviation {f32['max_rel_u']:.3g} of the limit span, "
            f"{f32['max_rel_y']:.3g} of the output excursion"
        )


def test_design_time_float32_number_is_what_the_c_does(example_artifacts):
    """The same closed-loop scenario with the host build in place of the numpy float32 law: same numbers."""
    a = artifact_mod.load(example_artifacts["pendulum"])
    mine = float32_fidelity(a)
    real = float32_fidelity(a, implementation=CLoop)
    assert real == mine
    assert mine.max_rel_u == a.data["checks"]["float32"]["max_rel_u"]
    assert mine.max_rel_u > 0  # float32 is not free, only small


def test_unstable_compensator_is_reported_in_design_analyze_and_checks(tmp_path):
    from gainlink.synthesis.random_plants import random_spec

    spec = random_spec(0, n=7, m=2, p=3, q=2, anti_windup="backcalc", u_limit=100.0)
    result = design_spec(parse_spec(spec))
    comp = result.artifact["checks"]["compensator"]
    assert not comp["stable"] and max(abs(complex(*z)) for z in comp["unstable_poles"]) > 1.5
    warning = next(w for w in result.warnings if "compensator" in w)
    assert "unstable" in warning and "loop closed" in warning and "broken sensor path" in warning
    a = artifact_mod.from_dict(result.artifact)
    assert comp["spectral_radius"] == pytest.approx(np.max(np.abs(jacobian_poles(a))), rel=1e-9)
    # the CLI: analyze and design print it for a spec file
    from gainlink.hil.plants.toml_write import dumps

    (tmp_path / "spec.toml").write_text(dumps(spec))
    out = run_cli("analyze", tmp_path / "spec.toml")
    assert out.code == 0 and "-> UNSTABLE" in out.out
    out = run_cli("design", tmp_path / "spec.toml", "--out", tmp_path / "d")
    assert out.code == 0 and "(UNSTABLE)" in out.out and "float32 in closed loop" in out.out


def test_flexible_structure_observer_is_ill_conditioned_and_float32_warns(flexible):
    result, a = flexible["as_designed"]
    _, V = np.linalg.eig(a.Ad - a.L @ a.Cd)
    assert np.linalg.cond(V) > 1e3
    f32 = result.float32
    assert f32.max_rel_u > THRESHOLD
    assert any('realization = "balanced"' in w and "float32" in w for w in result.warnings)


def test_balanced_realisation_cuts_the_float32_deviation_tenfold(flexible):
    base = flexible["as_designed"][0].float32.max_rel_u
    balanced = flexible["balanced"][0].float32.max_rel_u
    schur = flexible["schur"][0].float32.max_rel_u
    print(
        f"float32 closed-loop deviation (of the limit span): as_designed {base:.3g}, balanced {balanced:.3g} "
        f"({base / balanced:.0f}x less), schur {schur:.3g}"
    )
    assert balanced * 10 <= base
    assert flexible["balanced"][0].float32.ok and not flexible["balanced"][0].warnings
    # the real C in the balanced realisation gives the same deviation in the same scenario
    _, a = flexible["balanced"]
    assert float32_fidelity(a, implementation=CLoop).max_rel_u == balanced


def test_every_realisation_has_the_same_float64_behaviour(flexible):
    _, base = flexible["as_designed"]
    sim = simulate_linear(base, steps=3000, x0=[1e-3, 0, 0, 0], reference=[0.05], noise_std=1e-4, seed=2)
    want = ReferenceLoop(base).run(sim.y, sim.r)
    span = base.u_max - base.u_min
    for kind in ("balanced", "schur"):
        _, a = flexible[kind]
        got = ReferenceLoop(a).run(sim.y, sim.r)
        assert np.max(np.abs(got.u - want.u) / span) < 1e-9, kind
        assert np.array_equal(got.saturated, want.saturated), kind
        np.testing.assert_allclose(got.z, want.z, rtol=0, atol=1e-9 * max(1.0, np.abs(want.z).max()))
        # the estimates are the same up to the change of coordinates
        T = np.array(a.data["realization"]["T"])
        np.testing.assert_allclose(got.xh, want.xh @ T.T, rtol=0, atol=1e-9 * np.abs(want.xh @ T.T).max())


def test_realisation_is_recorded_and_every_gain_recomputable(flexible):
    _, base = flexible["as_designed"]
    assert "realization" not in base.data
    for kind in ("balanced", "schur"):
        _, a = flexible[kind]
        rec = a.data["realization"]
        assert rec["kind"] == kind
        T = np.array(rec["T"])
        Ti = np.linalg.inv(T)
        for key in ("Ad", "Bd", "Cd", "K", "L"):  # the design's own matrices are those of the plain design
            np.testing.assert_array_equal(np.array(rec["design"][key]), getattr(base, key), err_msg=key)
        for key, want in (
            ("Ad", T @ base.Ad @ Ti),
            ("Bd", T @ base.Bd),
            ("Cd", base.Cd @ Ti),
            ("K", base.K @ Ti),
            ("L", T @ base.L),
        ):
            np.testing.assert_allclose(getattr(a, key), want, rtol=0, atol=1e-12 * max(1.0, np.abs(want).max()))
        np.testing.assert_array_equal(a.Ki, base.Ki)
        np.testing.assert_array_equal(a.Kaw, base.Kaw)
        if kind == "schur":
            np.testing.assert_allclose(T @ T.T, np.eye(a.n), atol=1e-12)
            F = a.Ad - a.L @ a.Cd
            assert np.all(np.abs(np.tril(F, -2)) < 1e-9 * np.abs(F).max())  # upper quasi-triangular
        # editing T (or a transformed matrix) without the rest is caught
        bent = dict(a.data)
        bent["realization"] = dict(rec, T=(T * 1.001).tolist())
        with pytest.raises(artifact_mod.ArtifactError, match="realization"):
            artifact_mod.from_dict(artifact_mod.seal(bent))


def test_c_runs_the_realisation_it_is_given(flexible):
    """The host build of the balanced artifact passes the one-step check against the float64 law."""
    _, a = flexible["balanced"]
    sim = simulate_linear(a, steps=2000, x0=[1e-3, 0, 0, 0], reference=[0.05], noise_std=1e-4, seed=3)
    trace = NativeLoop(a).run(sim.y, sim.r)
    check = one_step_check(a, sim.y, sim.r, trace)
    assert check.passed, check.first_failure.describe("native")


def test_implementation_table_is_checked(tmp_path):
    text = (EXAMPLES / "pendulum.toml").read_text()
    for extra, needle in (
        ('[implementation]\nrealization = "modal"\n', "implementation.realization must be one of"),
        ("[implementation]\nfloat32_check = 1\n", "float32_check must be true or false"),
        ('[implementation]\nrealisation = "balanced"\n', "unknown key 'realisation'"),
    ):
        path = tmp_path / "spec.toml"
        path.write_text(text + "\n" + extra)
        assert_refused(("design", path, "--out", tmp_path / "out"), needle, tmp_path)
    path.write_text(text + '\n[implementation]\nrealization = "balanced"\nfloat32_check = false\n')
    res = run_cli("design", path, "--out", tmp_path / "out")
    assert res.code == 0 and "float32 in closed loop" not in res.out
    a = artifact_mod.load(tmp_path / "out" / "gains.json")
    assert a.data["realization"]["kind"] == "balanced" and "float32" not in a.data["checks"]


pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def test_module_docstring_figures_are_what_the_examples_measure(example_artifacts):
    """fidelity's docstring quotes the float32 closed-loop deviation of each example: each figure must be the
    one the example's design records today, to the two digits printed (wood_berry said 6.2e-7 on main; 8.9e-7)."""
    import re

    import gainlink.laws.lq.fidelity as fidelity

    text = " ".join(fidelity.__doc__.split())
    quoted = dict(re.findall(r"(\w+) (\d\.\de-\d+)", text[text.index("Measured on the examples") :]))
    assert set(quoted) == set(example_artifacts), quoted
    for name, path in example_artifacts.items():
        measured = artifact_mod.load(path).data["checks"]["float32"]["max_rel_u"]
        assert float(quoted[name]) == float(f"{measured:.1e}"), (name, quoted[name], measured)
