"""A scheduled spec's bad inputs through the CLI (one line, exit 2, nothing written), the schema-2 artifact
(validation, hash, coefficients against their design), replay with external sigma and the one-step check,
``Artifact.controller(sigma=...)`` and ``gl.design(..., schedule=...)``."""

from __future__ import annotations

import copy
import json

import control as ct
import gainlink as gl
import numpy as np
import pytest
from gainlink.errors import ArtifactError, DataError
from gainlink.fileio import atomic_write_text
from gainlink.shipping import artifact as artifact_mod
from schedule_cases import TANK, external_tank, tank_dict
from support.cli import assert_refused, run_cli
from support.designs import designed


def _toml(data: dict) -> str:
    from gainlink.hil.plants import toml_write

    return toml_write.dumps(data, header="test spec")


def _point(i: int):
    return lambda d: d["schedule"]["plant"][i]


BAD = {
    "one point": (lambda d: d["schedule"].update(points=[0.5], plant=d["schedule"]["plant"][:1]), "at least two"),
    "not increasing": (lambda d: d["schedule"].update(points=[0.04, 1.0, 0.25]), "strictly increasing"),
    "plants and points differ": (lambda d: d["schedule"]["plant"].pop(), "one per point|but there are"),
    "other state count": (lambda d: _point(1)(d).update(A=[[-1.0]], B=[[1.0]], C=[[1.0]]), "schedule.plant\\[1\\]"),
    "other state names": (lambda d: _point(2)(d).update(states=["h", "q"]), "same coordinates"),
    "sigma unknown": (lambda d: d["schedule"].update(sigma="flow"), "neither a plant output"),
    "trim outside limits": (lambda d: _point(2)(d).update(u_op=[1.5]), "outside the limits"),
    "rate_max zero": (lambda d: d["schedule"].update(rate_max=0.0), "rate_max must be a finite number > 0"),
    "rate_max negative": (lambda d: d["schedule"].update(rate_max=-1.0), "rate_max"),
    "filter_tau negative": (lambda d: d["schedule"].update(filter_tau=-0.1), "filter_tau"),
    "rate_certified not a bool": (lambda d: d["schedule"].update(rate_certified="no"), "true or false"),
    "rate_certified false alone": (lambda d: d["schedule"].update(rate_certified=False), "give rate_max"),
    "certify_budget zero": (lambda d: d["schedule"].update(certify_budget=0), "certify_budget must be a finite"),
    "transfer function": (lambda d: d["plant"].update(kind="transfer_function"), "state-space plants"),
    "matrices in [plant]": (lambda d: d["plant"].update(A=[[0.0]]), "keeps only kind and the signal names"),
    "balanced realisation": (lambda d: d.update(implementation={"realization": "balanced"}), "cannot be scheduled"),
    "no integral action": (lambda d: d.pop("integral"), "integral action on every input"),
    "other anti-windup": (lambda d: d["limits"].update(anti_windup="backcalc"), "must be 'velocity'"),
    "operating_point table": (lambda d: d.update(operating_point={"u_op": [0.1]}), "drop \\[operating_point\\]"),
    "unknown key": (
        lambda d: d["schedule"].update(rate=1.0),
        "unknown key 'rate' \\(did you mean 'rate_max'\\?\\) in schedule",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scheduled_spec_is_one_line_exit_2(case, tmp_path):
    """Each bad input of issue 18 and of the design document: one line naming it, exit 2, nothing written."""
    import re

    edit, pattern = BAD[case]
    data = tank_dict()
    edit(data)
    spec = tmp_path / "spec.toml"
    spec.write_text(_toml(data))
    res = assert_refused(("design", spec, "--out", tmp_path / "out"), "", tmp_path)
    assert re.search(pattern, res.err), res.err


def test_velocity_without_schedule_is_refused(tmp_path):
    data = tank_dict()
    sched = data.pop("schedule")
    data["plant"].update({k: sched["plant"][0][k] for k in ("A", "B", "C")})
    spec = tmp_path / "spec.toml"
    spec.write_text(_toml(data))
    assert_refused(("design", spec, "--out", tmp_path / "out"), "needs a [schedule]", tmp_path)


def test_lmi_solver_failure_is_one_line_exit_2(tmp_path, monkeypatch):
    """Both LMI solvers failing (made to fail here: nothing real fails on demand) is one line, exit 2, no file."""
    from gainlink.synthesis import lmi

    def broken(*_args, **_kwargs):
        raise RuntimeError("numerical trouble")

    monkeypatch.setattr(lmi, "_clarabel", broken)
    monkeypatch.setattr(lmi, "_scs", broken)
    assert_refused(("design", TANK, "--out", tmp_path / "out"), "LMI solver failed", tmp_path)


@pytest.fixture(scope="module")
def external(tmp_path_factory):
    """The external-sigma tank designed and written: (path, artifact)."""
    path = tmp_path_factory.mktemp("sched") / "gains.json"
    artifact_mod.write(path, designed(external_tank(rate_max=2.0)))
    return path, artifact_mod.load(path)


def test_scheduled_artifact_validates_and_is_sealed(external, tmp_path):
    """schema 2 loads and validates; an edited number breaks the hash; a coefficient edited and resealed no longer
    matches its design matrices and is refused."""
    path, _art = external
    assert run_cli("validate", path).code == 0
    data = json.loads(path.read_text())
    tampered = copy.deepcopy(data)
    tampered["schedule"]["point"][1]["Kx"][0][0] *= 1.0001
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(tampered))
    assert_refused(("validate", bad), "sha256 mismatch", tmp_path)
    atomic_write_text(bad, artifact_mod.render(artifact_mod.seal(tampered)))
    with pytest.raises(ArtifactError, match=r"schedule.point\[1\].Kx is not the coefficient"):
        artifact_mod.load(bad)
    flat = copy.deepcopy(data)
    flat["Ad"] = [[1.0]]
    with pytest.raises(ArtifactError, match="schema"):
        artifact_mod.from_dict(artifact_mod.seal(flat))


def test_unscheduled_tools_refuse_a_scheduled_artifact(external):
    """Each part of the lq law (its float64 law, its float32 model, its C and gain set, its one operating point and
    plant) refuses the scheduled law's artifact in one line naming the part, the law it runs and its sigma."""
    _path, art = external
    from gainlink.engines.native import NativeLoop
    from gainlink.laws.lq.model import Float32Loop
    from gainlink.proof.reference import ReferenceLoop
    from gainlink.proof.sampled_plant import SampledPlant
    from gainlink.shipping.codegen import render_c

    parts = {
        "ReferenceLoop": ReferenceLoop,
        "the float32 law": Float32Loop,
        "codegen": render_c,
        "the native engine": NativeLoop,
        "the artifact's own plant": SampledPlant.from_artifact,
        "safe_command": lambda a: a.safe_command,
        "r_op": lambda a: a.r_op,
        "design_plant": lambda a: a.design_plant(),
    }
    for what, make in parts.items():
        with pytest.raises(ArtifactError) as refused:
            make(art)
        line = str(refused.value)
        assert "\n" not in line and line.startswith(f"{what} is the lq law's"), line
        assert "runs the scheduled-float32 law (the velocity-form law scheduled on load)" in line, line


def _sim_csv(art, path, N=300):
    """A closed loop of the scheduled law around the interpolated plant, sigma ramping across the envelope (with a
    non-finite sample and a non-finite sigma in it), written as a replay input with s0."""
    from gainlink.laws.scheduled.reference import ScheduledLoop
    from gainlink.proof.sampled_plant import SampledPlant

    S = art.schedule
    sig = np.clip(np.linspace(-0.1, 1.2, N), None, None)
    loop, plant = ScheduledLoop(art), SampledPlant(*S.plant_at(0.04), u_op=S.u_op[0], y_op=S.y_op[0])
    rows = ["t,y0,r0,s0"]
    for k in range(N):
        y, r, s = plant.outputs(), np.array([0.2 + 0.1 * (k > 50)]), sig[k]
        y_rec = [np.nan] if k == 120 else y
        s_rec = np.nan if k == 121 else s
        u = loop.step(y_rec, r, [s_rec]).u
        rows.append(f"{k * art.Ts!r},{float(y_rec[0])!r},{float(r[0])!r},{float(s_rec)!r}")
        plant.advance(u)
    path.write_text("\n".join(rows) + "\n")


def test_replay_with_external_sigma_and_one_step_check(external, tmp_path):
    """replay reads s0, writes sigma, flags and the whole state; --compare runs the one-step check on both; a
    trace bent at one step fails it, naming the step."""
    path, art = external
    inp, out = tmp_path / "in.csv", tmp_path / "out.csv"
    _sim_csv(art, inp)
    res = run_cli("replay", path, "--input", inp, "--output", out)
    assert res.code == 0, res.err
    first, *lines = out.read_text().splitlines()
    assert first == "# numeric=float64"  # the float64 law's trace: checked as such when compared
    header = lines[0].split(",")
    assert header[:7] == ["t", "u0", "sat0", "fault", "sigma", "sflags", "d0"] and header[-1] == "started"
    body = [line.split(",") for line in lines[1:]]
    assert body[120][3] == "1" and int(body[121][5]) & 1 and int(body[0][5]) & 2  # fault, held, clipped
    assert run_cli("replay", path, "--input", inp, "--output", tmp_path / "o2.csv", "--compare", out).code == 0
    body[200][1] = repr(float(body[200][1]) + 1e-6)
    bent = tmp_path / "bent.csv"
    bent.write_text("\n".join([",".join(header)] + [",".join(r) for r in body]) + "\n")
    assert_refused(("replay", path, "--input", inp, "--output", tmp_path / "o3.csv", "--compare", bent), "step 200: u0")


def test_replay_without_s_columns_is_refused(external, tmp_path):
    path, _ = external
    inp = tmp_path / "in.csv"
    inp.write_text("y0,r0\n0.1,0.1\n")
    assert_refused(("replay", path, "--input", inp, "--output", tmp_path / "out.csv"), "lacks column(s) s0", tmp_path)


def test_api_replay_and_controller_at_sigma(external):
    """gl.replay takes s; controller(sigma) is the frozen law there (python-control's poles of the hand-built law
    from the interpolated per-point coefficients); sigma is required exactly for a scheduled artifact."""
    _, art = external
    tr = gl.replay(art, np.full((5, 1), 0.25), np.full((5, 1), 0.25), s=np.full((5, 1), 0.25))
    assert tr.u.shape == (5, 1) and np.all(tr.sigma == 0.25)
    with pytest.raises(DataError, match="give s"):
        gl.replay(art, np.full((5, 1), 0.25))
    with pytest.raises(ArtifactError, match="sigma"):
        art.controller()
    S, Ts = art.schedule, art.Ts
    for sigma in (0.04, 0.6):
        c = S.coefficients_at(sigma)
        hand = np.block([[c["F"] - c["G"] @ c["Kx"], -c["G"] @ c["Kz"] / Ts], [np.zeros((1, art.n)), np.eye(1)]])
        got = np.sort_complex(ct.poles(art.controller(sigma=sigma)))
        assert np.allclose(got, np.sort_complex(np.linalg.eigvals(hand)), atol=1e-10)


@pytest.mark.slow(cpu=5)
def test_gl_design_with_a_schedule_of_statespaces():
    """gl.design(sys, schedule={..., "plant": [StateSpace, ...]}) designs the same artifact as the spec dict."""
    data = external_tank()
    names = {"states": ["q", "h"], "inputs": ["u"], "outputs": ["h"]}
    systems = [ct.ss(p["A"], p["B"], p["C"], [[0.0]], **names) for p in data["schedule"]["plant"]]
    trims = [{k: p[k] for k in ("u_op", "y_op", "x_op")} for p in data["schedule"]["plant"]]
    sched = dict(data["schedule"], plant=[{"A": s.A, "B": s.B, "C": s.C} | t for s, t in zip(systems, trims)])
    art = gl.design(
        systems[0], Ts=data["Ts"], name=data["name"], controller=data["controller"], integral=data["integral"],
        observer=data["observer"], limits=data["limits"], schedule=sched,
    )  # fmt: skip
    want = artifact_mod.from_dict(designed(external_tank()))  # the spec dict's design: once per run, six modules use it
    for k in ("Kx", "Kz", "F", "G", "Ly"):
        assert np.allclose(art.schedule.coef[k], want.schedule.coef[k], rtol=1e-12, atol=1e-15)
