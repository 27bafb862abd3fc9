"""``gainlink linearize FMU --schedule NAME=v1,v2,...``: the FMU trimmed at each point (solved, not only
evaluated) against hand-derived trims, the scheduled spec it writes designs, and its bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import PlantError
from gainlink.fileio import read_toml
from gainlink.hil.plants.build import build_fmu
from gainlink.hil.plants.trim import solve
from support.cli import assert_refused, run_cli

TEMPLATE = """\
name = "hover"
Ts = 0.01

[controller]
method = "lqr"
Q_diag = [10.0, 1.0]
R_diag = [1.0]

[integral]
outputs = ["z"]
Q_diag = [10.0]

[observer]
method = "kalman"
W_diag = [1e-4, 1e-2]
V_diag = [1e-6]

[limits]
u_min = [0.0]
u_max = [1.0]
anti_windup = "velocity"
"""


def test_newton_trims_a_tank_by_hand():
    """The tank of examples/tank_scheduled.toml at level h: q = u = c sqrt(h) solves dq/dt = dh/dt = 0 (c = 0.4);
    from a guess of zero flow, where the equations do not depend on u yet."""
    c, tau, h = 0.4, 0.1, 0.36

    def evaluate(z):
        q, u = z
        g = np.array([(u - q) / tau, q - c * np.sqrt(h)])
        return g, np.array([[-1 / tau, 1 / tau], [1.0, 0.0]])

    z, _, res = solve(evaluate, np.array([0.0, 0.0]))
    assert np.allclose(z, [c * np.sqrt(h)] * 2, rtol=1e-12) and res < 1e-10
    with pytest.raises(PlantError, match="did not converge"):
        solve(lambda z: (np.array([z[0] ** 2 + 1.0]), np.array([[2 * z[0]]])), np.array([1.0]))


@pytest.fixture(scope="module")
def multirotor():
    """The project's multirotor_vertical FMU and its parameters read from its model description."""
    from fmpy import read_model_description

    path = build_fmu("multirotor_vertical")
    start = {v.name: float(v.start) for v in read_model_description(str(path)).modelVariables if v.start is not None}
    return path, start


@pytest.fixture(scope="module")
def hover(multirotor, tmp_path_factory):
    """The multirotor scheduled on its mass (0.8, 1.0, 1.5, the altitude held at 2 m) with TEMPLATE by
    `linearize --json`, and that spec designed: (spec path, printed JSON, linearize's stderr, design's result).
    One linearization and one design (with its certificate) for the tests that read them, on one worker."""
    path, _ = multirotor
    folder = tmp_path_factory.mktemp("hover")
    spec = folder / "spec.toml"
    js, err = _schedule_json(path, spec)
    return spec, js, err, run_cli("design", spec, "--out", folder / "design")


ON_HOVER = pytest.mark.xdist_group("test_schedule_trim_hover")


@pytest.mark.slow(cpu=10)
@ON_HOVER
def test_schedule_on_a_parameter_trims_hover_throttle(multirotor, hover):
    """Scheduled on the mass (a parameter: sigma is external) with the altitude held: at each mass the throttle
    is sqrt(m g / k_T) and B = [0, 2 k_T u / m] (the model's own hand-derived hover, from its parameters), and
    the spec designs a schema-2 artifact."""
    _, p = multirotor
    spec, _, _, design = hover
    masses = [0.8, 1.0, 1.5]
    data, _ = read_toml(spec, what="spec", error=ValueError)
    sched = data["schedule"]
    assert sched["sigma"] == "mass" and sched["external"] == ["mass"] and sched["points"] == masses
    for m, pt in zip(masses, sched["plant"]):
        u = np.sqrt(m * p["g"] / p["k_T"])
        assert pt["u_op"][0] == pytest.approx(u, rel=1e-9)
        assert pt["x_op"] == pytest.approx([2.0, 0.0], abs=1e-9) and pt["y_op"] == pytest.approx([2.0])
        assert np.allclose(pt["B"], [[0.0], [2 * p["k_T"] * u / m]], rtol=1e-6)
    assert design.code == 0, design.err
    assert '"schema_version": 2' in (spec.parent / "design" / "gains.json").read_text()


@pytest.mark.slow(cpu=5)
def test_the_default_spec_of_a_slow_loop_designs_its_certificate_proved_in_float64(multirotor, tmp_path):
    """The spec `linearize --schedule` writes without a template (the multirotor on its mass) needs a Lyapunov
    matrix with a condition number near 1e7: Clarabel stopped short of its tolerances (InsufficientProgress) and the
    design was refused ("the LMI solver failed"). The LMIs are solved in a whitened basis and their candidate is
    proved in ball arithmetic; the common P is proved again here, independently, on a dense grid of masses (not only
    the hull's vertices)."""
    from gainlink.laws.scheduled.lpv import velocity_loop
    from gainlink.shipping.artifact import load

    path, _ = multirotor
    spec, out = tmp_path / "spec.toml", tmp_path / "design"
    assert run_cli("linearize", path, "--schedule", "mass=0.8,1.2,1.6", "--at", "z=2", "--out", spec).code == 0
    res = run_cli("design", spec, "--out", out)
    assert res.code == 0, res.err
    art = load(out / "gains.json")
    var = art.checks["schedule"]["variation"]
    assert var["common_lyapunov"] and var["rate_max"] is None and var["rate_certified"]
    P = np.array(var["certificate"]["P"][0])  # on [x; delta; u_prev; y_prev], e_prev = -Ci y_prev (r = 0)
    S = art.schedule
    r = P.shape[0]
    E = np.vstack([np.eye(r), np.hstack([np.zeros((art.q, r - art.p)), -art.Ci])])
    for mass in np.linspace(S.points[0], S.points[-1], 201):
        A = velocity_loop(S.plant_at(mass), S.coefficients_at(mass), Ci=art.Ci)[:r] @ E
        assert np.linalg.eigvalsh(P - A.T @ P @ A)[0] > 0, mass


def test_schedule_on_an_output_state(multirotor, tmp_path):
    """Scheduled on the altitude z (an output that is a state: held there): hover at every altitude."""
    path, p = multirotor
    spec = tmp_path / "spec.toml"
    res = run_cli("linearize", path, "--schedule", "z=1,2,5", "--out", spec)
    assert res.code == 0, res.err
    data, _ = read_toml(spec, what="spec", error=ValueError)
    assert data["schedule"]["sigma"] == "z" and data["schedule"]["external"] == []
    for z, pt in zip((1.0, 2.0, 5.0), data["schedule"]["plant"]):
        assert pt["x_op"] == pytest.approx([z, 0.0], abs=1e-9)
        assert pt["u_op"][0] == pytest.approx(np.sqrt(p["mass"] * p["g"] / p["k_T"]), rel=1e-9)
    assert data["limits"]["anti_windup"] == "velocity" and data["integral"]["outputs"] == ["z"]


@pytest.mark.parametrize(
    ("schedule", "extra", "message"),
    [
        ("throttle=0.5,0.6", [], "an input is what the trim solves for"),
        ("mass=1.0,0.8", ["--at", "z=2"], "strictly increasing"),
        ("mass=1.0", ["--at", "z=2"], "at least two"),
        ("mass=1,x", [], "NAME=v1,v2"),
        ("payload=1,2", [], "payload"),
    ],
)
def test_bad_schedule_is_one_line_exit_2(multirotor, tmp_path, schedule, extra, message):
    path, _ = multirotor
    out = tmp_path / "spec.toml"
    assert_refused(("linearize", path, "--schedule", schedule, *extra, "--out", out), message, tmp_path)


def test_trim_outside_the_limits_is_refused(multirotor, tmp_path):
    """Limits that cannot hold the heaviest point (throttle 0.70 above u_max 0.6): refused, nothing written."""
    path, _ = multirotor
    tmpl = tmp_path / "tmpl.toml"
    tmpl.write_text(TEMPLATE.replace("u_max = [1.0]", "u_max = [0.6]"))
    out = tmp_path / "spec.toml"
    argv = ("linearize", path, "--schedule", "mass=0.8,1.5", "--at", "z=2", "--template", tmpl, "--out", out)
    assert_refused(argv, "outside the limits", tmp_path)


# --- the fit of each point (issue 18, 1b per point) ----------------------------------------------------------


def _schedule_json(path, out, *extra):
    import json

    tmpl = out.with_name("tmpl.toml")
    tmpl.write_text(TEMPLATE)
    res = run_cli("linearize", path, "--schedule", "mass=0.8,1.0,1.5", "--at", "z=2", "--template", tmpl,
                  "--out", out, "--json", *extra)  # fmt: skip
    assert res.code == 0, res.err
    return json.loads(res.out), res.err


@ON_HOVER
def test_each_point_records_its_fit_and_it_is_good(hover):
    """Each point's model fits the FMU (small steps from its trim through the interface runs use): NRMSE and final
    error far below 5 %, recorded next to the point's plant in the spec and per point in --json, no warning."""
    spec, js, err, design = hover
    assert "poorly" not in err
    data, _ = read_toml(spec, what="spec", error=ValueError)
    assert data["linearization"]["interface"] == js["linearization"]["interface"] and "fit" not in data["linearization"]
    assert [p["sigma"] for p in js["points"]] == [0.8, 1.0, 1.5]
    for point, pt in zip(js["points"], data["schedule"]["plant"]):
        assert point["fit"] == pt["fit"] and point["fit_steps"] == pt["fit_steps"] > 0
        assert pt["fit"]["z"]["nrmse"] < 1e-3 and pt["fit"]["z"]["final_error"] < 1e-3, pt["fit"]
        assert pt["fit_amplitude"]["throttle"] > 0 and "fit_warning" not in pt
    assert design.code == 0, design.err  # the record does not stop a design


def test_a_poor_fit_at_a_point_warns_naming_the_point(multirotor, monkeypatch, caplog, tmp_path):
    """Steps far too large for a linear model (as the single-point test provokes it, here 5x the output's value):
    the thrust k_T u^2 bends most where the hover throttle is lowest, so the lightest point fits poorly and warns
    in one line that names it, with the plant's nonlinearity as the cause; the heavier points stay under 5 %."""
    from gainlink.hil.plants import step_response

    monkeypatch.setattr(step_response, "LEVEL", 5.0)
    path, _ = multirotor
    spec = tmp_path / "spec.toml"
    js, _ = _schedule_json(path, spec)
    data, _ = read_toml(spec, what="spec", error=ValueError)
    warnings = [r.getMessage() for r in caplog.records if "fits the FMU poorly" in r.getMessage()]
    assert len(warnings) == 1 and "\n" not in warnings[0] and "at mass = 0.8:" in warnings[0], warnings
    assert "likely cause: the plant's nonlinearity at that amplitude" in warnings[0]
    light, *heavy = data["schedule"]["plant"]
    assert light["fit_warning"] in warnings[0] and js["points"][0]["fit_warning"] == light["fit_warning"]
    assert light["fit"]["z"]["final_error"] > 0.05
    assert all("fit_warning" not in pt and pt["fit"]["z"]["final_error"] < 0.05 for pt in heavy)
    assert "POOR at mass = 0.8" in spec.read_text().splitlines()[1]
