"""Model validity: linearize and every run agree on the plant, linearize checks the model it wrote, and every run
closes the law around the design's own model too (the model twin).

The case from the issue: OpenModelica's Mass_Damper (fetched at test time from the gemseo-fmu wheel, pinned by
sha256) has both interfaces; its Co-Simulation export steps with explicit Euler, which at 1 ms removes the
damping. Oracles, independent of the code under test: the textbook mass-spring-damper with the FMU's own
parameters, solved exactly under held inputs (scipy's matrix exponential) and by explicit Euler (what the
Co-Simulation export does, read off its first steps); python-control's closed loop of the artifact for the model
twin; hand-computed numbers for the mismatch figures.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gainlink.errors import SpecError
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.model_twin import MISMATCH_WARN, model_mismatch
from gainlink.hil.loop.report import summary_text, write_report
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.hil.plants.build import build_fmu
from gainlink.hil.plants.config import plant_from_config
from gainlink.hil.plants.fmi import read_description
from gainlink.hil.plants.fmu_interface import check_setup, choose_interface
from gainlink.shipping.artifact import load
from gainlink.spec import load_spec, parse_spec
from scipy.linalg import expm
from support.cli import run_cli
from support.hil import udp_transport
from support.thirdparty import TEMPLATE, gemseo_fmu

# One worker runs this module (make test: --dist loadgroup): the mass-damper FMU and its design, made once.
# one worker runs the module (34 CPU-s, its HIL runs among them): started first
pytestmark = [pytest.mark.xdist_group("test_model_validity"), pytest.mark.slow(cpu=34)]

TS = 1e-3
C_SPRING, D_DAMP, MASS = 1.0e4, 10.0, 1.0


@pytest.fixture(scope="module")
def mass_damper():
    return gemseo_fmu("Mass_Damper.fmu")


def physics() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s'' = -(c/m)(s - 1) - (d/m) s' - f/m for the state (s, s') about rest at s = 1; output y = 0.5 - s."""
    A = np.array([[0.0, 1.0], [-C_SPRING / MASS, -D_DAMP / MASS]])
    return A, np.array([[0.0], [-1.0 / MASS]]), np.array([[-1.0, 0.0]])


def step_responses(Ad: np.ndarray, Bd: np.ndarray, C: np.ndarray, *, amplitude: float, steps: int) -> np.ndarray:
    x, out = np.zeros(2), []
    for _ in range(steps):
        x = Ad @ x + Bd[:, 0] * amplitude
        out.append((C @ x)[0])
    return np.array(out)


def exact_zoh(A, B):
    big = np.zeros((3, 3))
    big[:2, :2], big[:2, 2:] = A, B
    E = expm(big * TS)
    return E[:2, :2], E[:2, 2:]


# --- a: which interface runs -------------------------------------------------------------------------------


def _choice(path: Path, *, step: float | None, requested: str = "auto", start: dict | None = None):
    md = read_description(path)
    setup = check_setup(md, plant_args={"path": path}, solver={}, start=start or {})
    return choose_interface(md, requested=requested, step=step, setup=setup)


def test_cosimulation_that_removes_the_damping_is_not_used_and_the_verdict_is_cached(mass_damper):
    choice = _choice(mass_damper, step=TS)
    assert choice.interface == "me" and not choice.check.passed
    assert choice.check.max_error > 0.1 and "does not reproduce the Model Exchange derivatives" in choice.reason
    again = _choice(mass_damper, step=TS)
    assert again.check.cached and again.check.max_error == choice.check.max_error
    # The verdict is right: from the FMU's start (y = 0, released towards rest at y = -0.5), Model Exchange follows
    # the exact solution, Co-Simulation does not.
    A, B, C = physics()
    Ad = exact_zoh(A, B)[0]
    x, exact = np.array([-0.5, 0.0]), []
    for _ in range(300):
        x = Ad @ x
        exact.append(-0.5 + (C @ x)[0])
    for interface, bound in (("me", 1e-5), ("cs", None)):
        plant = plant_from_config({"kind": "fmu", "path": str(mass_damper), "interface": interface})
        ys = []
        for _ in range(300):
            plant.advance(u=np.zeros(1), dt=TS)
            ys.append(plant.outputs()[0])
        plant.close()
        err = np.abs(np.array(ys) - exact).max()
        assert err < bound if bound else err > 0.1, (interface, err)


@pytest.mark.parametrize("name, step", [("cart_pendulum", 0.01), ("quadrotor_lateral", 0.01)])
def test_a_sound_cosimulation_solver_is_kept(name, step):
    choice = _choice(build_fmu(name), step=step)
    assert choice.interface == "cs" and choice.check.passed and choice.check.max_error < 1e-3
    assert "reproduces the Model Exchange derivatives at Ts = 0.01 s" in choice.reason


def test_the_choice_without_a_check(mass_damper):
    assert _choice(mass_damper, step=TS, requested="cs").reason == 'forced by interface = "cs"'
    assert _choice(mass_damper, step=TS, requested="me").interface == "me"
    assert _choice(mass_damper, step=None).interface == "me"  # no run step to check at: the model itself
    me_only = _choice(build_fmu("mass_spring_damper3"), step=0.01)
    assert (me_only.interface, me_only.reason) == ("me", "the FMU has Model Exchange only")
    cs_only = _choice(build_fmu("wood_berry"), step=1.0)
    assert (cs_only.interface, cs_only.reason) == ("cs", "the FMU has Co-Simulation only")


# --- b: linearize checks what it wrote ------------------------------------------------------------------------


def _linearize_json(fmu: Path, out: Path, *extra: str):
    """The real command (a process of its own: its log lines reach its own stderr): the record and stderr."""
    gainlink = Path(sys.executable).parent / "gainlink"
    argv = [str(gainlink), "linearize", str(fmu), "--Ts", str(TS), "--out", str(out), "--json", *extra]
    res = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)["linearization"], res.stderr


def test_linearize_through_model_exchange_fits_and_records_why(mass_damper, tmp_path):
    rec, err = _linearize_json(mass_damper, tmp_path / "md.toml")
    assert "poorly" not in err
    assert rec["interface"] == "me" and rec["interface_check"]["max_error"] > 0.1
    assert rec["fit"]["y"]["nrmse"] < 1e-4 and rec["fit"]["y"]["final_error"] < 1e-4 and "fit_warning" not in rec
    spec = load_spec(tmp_path / "md.toml")  # the spec parser takes the record, and keeps it
    assert spec.linearization["fit"]["y"]["nrmse"] == rec["fit"]["y"]["nrmse"]


def test_forcing_cosimulation_is_caught_by_the_fit_warning(mass_damper, tmp_path):
    rec, err = _linearize_json(mass_damper, tmp_path / "md_cs.toml", "--interface", "cs")
    warnings = [line for line in err.splitlines() if "fits the FMU poorly" in line]
    assert len(warnings) == 1 and "likely cause: the FMU's own Co-Simulation solver or step" in warnings[0]
    assert rec["interface"] == "cs" and rec["fit_warning"] in warnings[0]
    # Oracle: explicit Euler of the textbook model against its exact discretisation, driven by the same step.
    A, B, C = physics()
    amplitude, steps = rec["fit_amplitude"]["f"], rec["fit_steps"]
    euler = step_responses(np.eye(2) + TS * A, TS * B, C, amplitude=amplitude, steps=steps)
    exact = step_responses(*exact_zoh(A, B), C, amplitude=amplitude, steps=steps)
    nrmse = np.sqrt(np.mean((euler - exact) ** 2)) / np.ptp(euler)
    assert rec["fit"]["y"]["nrmse"] == pytest.approx(nrmse, rel=1e-3) and nrmse > 0.05
    assert rec["fit"]["y"]["final_fmu"] == pytest.approx(euler[-1], rel=1e-6)
    assert rec["fit"]["y"]["final_model"] == pytest.approx(exact[-1], rel=1e-6)


def test_a_poor_fit_from_nonlinearity_is_named_so(monkeypatch, tmp_path):
    from gainlink.hil.plants import step_response
    from gainlink.hil.plants.linearize import linearize_to_spec

    monkeypatch.setattr(step_response, "LEVEL", 3.0)  # steps that swing the pendulum ~3 rad: far from linear
    fit = linearize_to_spec(fmu="cart_pendulum", at={}, out=tmp_path / "cp.toml", Ts=0.01).validity.fit
    assert fit.poor and fit.cause.startswith("the plant's nonlinearity at that amplitude")
    assert fit.worst_quarter < 0.5 * fit.worst


def test_the_record_reaches_the_artifact_and_its_keys_are_checked(mass_damper, tmp_path):
    _linearize_json(mass_damper, tmp_path / "md.toml", "--interface", "cs")
    (tmp_path / "t.toml").write_text(TEMPLATE, "utf-8")
    spec = tmp_path / "md.toml"
    text = spec.read_text()
    res = run_cli("design", spec, "--out", tmp_path)
    assert res.code == 0, res.err
    prov = load(tmp_path / "gains.json").provenance
    assert prov["plant_interface"] == 'cs: forced by interface = "cs"'
    assert "y NRMSE" in prov["plant_fit"] and "POOR" in prov["plant_fit"]
    import tomllib

    data = tomllib.loads(text)
    data["linearization"]["bogus"] = 1
    with pytest.raises(SpecError, match="unknown key 'bogus' in linearization"):
        parse_spec(data)


# --- c: the model twin -----------------------------------------------------------------------------------------


def test_mismatch_figures_by_hand():
    import control as ct
    import gainlink as gl

    art = gl.design(
        ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01),
        Q=[[1.0]],
        R=[[1.0]],
        W=[[1e-3]],
        V=[[1e-4]],
        u_min=[-1.0],
        u_max=[1.0],
    )
    t = np.arange(4) * 0.01
    y = np.array([[0.0], [1.0], [2.0], [1.0]])
    model = np.array([[0.0], [1.5], [2.0], [1.0]])
    mm = model_mismatch(t=t, y=y, r=np.zeros((4, 0)), model_y=model, artifact=art)
    # max |dy| 0.5 over the range 2.0; IAE about y_op = 0: 0.04 (plant) and 0.045 (model)
    assert mm.outputs["y0"]["max_dy_rel"] == pytest.approx(0.25) and mm.warn
    assert mm.iae["y0"]["ratio"] == pytest.approx(0.04 / 0.045)


@pytest.fixture(scope="module")
def designed(mass_damper, tmp_path_factory):
    """The issue's case: linearize (default path), design with the issue's LQI template."""
    tmp = tmp_path_factory.mktemp("md")
    (tmp / "template.toml").write_text(TEMPLATE, "utf-8")
    res = run_cli(
        "linearize", mass_damper, "--Ts", str(TS), "--out", tmp / "md.toml", "--template", tmp / "template.toml"
    )
    assert res.code == 0, res.err
    res = run_cli("design", tmp / "md.toml", "--out", tmp)
    assert res.code == 0, res.err
    return tmp / "gains.json"


def _scenario(gains: Path, fmu: Path, *, interface: str | None = None, **extra) -> dict:
    plant = {"kind": "fmu", "path": str(fmu)}
    if interface:
        plant["interface"] = interface
    return {
        "name": f"mass_damper_{interface or 'auto'}",
        "artifact": str(gains),
        "duration": 1.0,
        "plant": plant,
        "reference": {"r_y": {"kind": "step", "at": 0.3, "initial": -0.5, "value": -0.45}},
        **extra,
    }


def test_done_when_the_default_path_tracks_in_hil_and_agrees_with_its_model(designed, mass_damper, tmp_path):
    sc = _scenario(
        designed,
        mass_damper,
        mode="lockstep",
        controller="firmware",
        step_timeout=2.0,
        peer_timeout=4.0,
        transport=udp_transport(),
    )
    r = run_scenario(parse_scenario(sc))
    m, plant = r.metrics, r.info["plant"]
    assert r.complete and m["steps"] == 1000 and m["lost"] == 0
    assert m["outputs_final"]["y"] == pytest.approx(-0.45, abs=1e-3)
    assert plant["interface"] == "me" and plant["interface_check"]["cached"]  # linearize's verdict, reused
    assert m["model_twin"]["worst"] < 1e-3 and not m["model_twin"]["warning"]
    assert m["model_twin"]["start"] == "the plant's initial state"
    write_report(r, tmp_path / "report")
    text = (tmp_path / "report" / "summary.txt").read_text()
    assert "plant interface me: Co-Simulation does not reproduce" in text and "WARNING" not in text
    assert (tmp_path / "report" / "model_twin.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_done_when_forcing_cosimulation_is_caught_by_the_model_twin(designed, mass_damper, tmp_path):
    art = load(designed)
    r = run_scenario(
        parse_scenario({**_scenario(designed, mass_damper, interface="cs"), "transport": {}}), artifact=art
    )
    mt = r.metrics["model_twin"]
    assert mt["warning"] and mt["worst"] > MISMATCH_WARN
    assert mt["iae"]["r_y"]["ratio"] > 1.5  # the undamped plant needs more than twice the model's IAE
    text = summary_text(r)
    assert "WARNING: the design's model was checked through me, this run used cs" in text
    assert "WARNING: the plant departs from the design's model" in text


def test_the_model_twin_is_the_designed_closed_loop(designed, mass_damper):
    """Oracle: python-control's closed loop of the artifact (plant + unsaturated law), from the plant's initial
    deviation; the run stays unsaturated."""
    import control as ct

    art = load(designed)
    r = run_scenario(
        parse_scenario({**_scenario(designed, mass_damper), "controller": "reference", "transport": {}}), artifact=art
    )
    assert r.metrics["saturation_fraction"]["f"] == 0.0
    cl = art.closed_loop()
    tr = r.trace
    x0 = np.zeros(cl.nstates)
    x0[:2] = [-0.5, 0.0]  # the FMU starts at s = 0.5: 0.5 below the operating point s = 1
    U = np.vstack([tr.r[:, 0] - art.r_op[0], np.zeros(tr.t.size)])
    resp = ct.forced_response(cl, T=tr.t, U=U, X0=x0)
    np.testing.assert_allclose(tr.model_y[:, 0], art.y_op[0] + resp.outputs[0], atol=1e-9)


def test_campaign_runs_record_the_mismatch(designed, mass_damper, tmp_path):
    from gainlink.hil.campaign import run

    data = {
        "name": "interfaces",
        "kind": "sil",
        "seed": 1,
        "runs": 1,
        "artifact": str(designed),
        "scenario": {
            **{k: v for k, v in _scenario(designed, mass_damper).items() if k not in ("name", "artifact")},
            "controller": "reference",
        },
        "grid": [{"target": "plant.interface", "values": ["auto", "cs"]}],
    }
    result = run(data, out=tmp_path / "out", workers=1, plots=False)
    rows = {r["values"]["plant.interface"]: r for r in result.rows}
    assert rows["auto"]["measures"]["model_mismatch"] < 1e-3 and not rows["auto"]["measures"]["model_warning"]
    assert rows["cs"]["measures"]["model_mismatch"] > MISMATCH_WARN and rows["cs"]["measures"]["model_warning"]
    head = (tmp_path / "out" / "campaign.csv").read_text().splitlines()[0].split(",")
    assert "model_mismatch" in head and "model_iae_ratio" in head
    assert "model mismatch (plant against the design's model)" in (tmp_path / "out" / "summary.txt").read_text()


def test_pil_reports_the_model_twin_against_a_nonlinear_plant(example_artifacts, tmp_path):
    """The Cortex-M4F image in QEMU against the built-in nonlinear cart-pendulum from a 0.1 rad tilt: the
    pendulum model of the design describes it at this amplitude (small mismatch, no warning); the model twin
    starts at the same state (names match the spec's)."""
    res = run_cli(
        "pil",
        "run",
        example_artifacts["pendulum"],
        "--plant",
        "cart_pendulum",
        "--steps",
        "400",
        "--x0",
        "0",
        "0",
        "0.1",
        "0",
        "--reference",
        "0.2",
        "--out",
        tmp_path,
        "--json",
    )
    assert res.code == 0, res.err
    mt = json.loads(res.out)["model_twin"]
    assert mt["start"] == "the plant's initial state" and not mt["warning"]
    assert 0 < mt["worst"] < 0.05
    rows = (tmp_path / "pil.csv").read_text().splitlines()
    head = rows[0].split(",")
    first = dict(zip(head, map(float, rows[1].split(","))))
    assert first["model_y1"] == pytest.approx(first["y1"], abs=1e-12)  # both start at theta = 0.1
