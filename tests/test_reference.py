"""The float64 reference loop against an independent pure-Python transcription of the law in docs/design.md
("The control law")."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gainlink.laws import design as design_spec
from gainlink.proof.reference import ReferenceLoop
from gainlink.proof.replay_io import read_samples
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import parse_spec
from gainlink.synthesis.random_plants import random_spec
from support.cli import assert_refused, run_cli


def matvec(A, x):
    return [sum(a * b for a, b in zip(row, x)) for row in A]


def independent_law(data: dict, Y, R):
    """The step of docs/design.md written with lists and loops only, from the artifact's JSON dict."""
    n, m, p, q = data["n"], data["m"], data["p"], data["q"]
    Ad, Bd, Cd, Dd, K, L = (data[k] for k in ("Ad", "Bd", "Cd", "Dd", "K", "L"))
    Ci = data.get("Ci", [])
    Ki = data.get("Ki", [[] for _ in range(m)])
    Kaw = data.get("Kaw", [])
    M = data.get("M")
    Ts, aw, form = data["Ts"], data["anti_windup"], data["observer_form"]
    lo, hi = data["u_min"], data["u_max"]
    xh, z = [0.0] * n, [0.0] * q
    out = []
    for y, r in zip(Y, R):
        if not all(math.isfinite(v) for v in list(y) + list(r)):
            out.append(([min(max(0.0, lo[i]), hi[i]) for i in range(m)], [False] * m, True, list(xh), list(z)))
            continue
        if form == "current":
            innov = [y[i] - matvec(Cd, xh)[i] for i in range(p)]
            xc = [xh[i] + matvec(M, innov)[i] for i in range(n)]
        else:
            xc = xh
        v = [-(matvec(K, xc)[i]) - (matvec(Ki, z)[i] if q else 0.0) for i in range(m)]
        u = [min(max(v[i], lo[i]), hi[i]) for i in range(m)]
        sat = [u[i] != v[i] for i in range(m)]
        e = [r[j] - matvec(Ci, y)[j] for j in range(q)]
        if aw == "none" or (aw == "clamp" and not any(sat)):
            z = [z[j] + Ts * e[j] for j in range(q)]
        elif aw == "backcalc":
            corr = matvec(Kaw, [u[i] - v[i] for i in range(m)]) if q else []
            z = [z[j] + Ts * e[j] + corr[j] for j in range(q)]
        if form == "current":
            xh = [matvec(Ad, xc)[i] + matvec(Bd, u)[i] for i in range(n)]
        else:
            innov = [y[i] - matvec(Cd, xh)[i] - matvec(Dd, u)[i] for i in range(p)]
            xh = [matvec(Ad, xh)[i] + matvec(Bd, u)[i] + matvec(L, innov)[i] for i in range(n)]
        out.append((u, sat, False, list(xh), list(z)))
    return out


CASES = [
    dict(n=3, m=1, p=1, q=1, form="predictor", anti_windup="none"),
    dict(n=3, m=1, p=2, q=1, form="current", anti_windup="clamp"),
    dict(n=4, m=2, p=2, q=2, form="predictor", anti_windup="backcalc", feedthrough=True),
    dict(n=5, m=2, p=3, q=1, form="current", anti_windup="backcalc"),
    dict(n=4, m=2, p=2, q=0, form="predictor", anti_windup="none"),
]


@pytest.mark.parametrize(
    "case", CASES, ids=lambda c: f"n{c['n']}m{c['m']}p{c['p']}q{c['q']}-{c['form']}-{c['anti_windup']}"
)
def test_reference_matches_independent_law_on_random_inputs(case):
    a = artifact_mod.from_dict(design_spec(parse_spec(random_spec(7, **case))).artifact)
    rng = np.random.default_rng(1)
    N = 200
    Y = 3.0 * rng.standard_normal((N, a.p))  # large enough to saturate the +-1 limits
    R = rng.standard_normal((N, a.q))
    Y[50, 0] = np.nan
    R[90:92] = np.inf if a.q else R[90:92]
    trace = ReferenceLoop(a).run(Y, R)
    expected = independent_law(a.data, Y.tolist(), R.tolist())
    for k, (u, sat, fault, xh, z) in enumerate(expected):
        np.testing.assert_allclose(trace.u[k], u, rtol=1e-12, atol=1e-12, err_msg=f"step {k}")
        assert list(trace.saturated[k]) == sat and trace.fault[k] == fault, f"step {k}"
        np.testing.assert_allclose(trace.xh[k], xh, rtol=1e-11, atol=1e-11, err_msg=f"step {k}")
        np.testing.assert_allclose(trace.z[k], z, rtol=1e-11, atol=1e-11, err_msg=f"step {k}")
    assert trace.saturated.any() and not trace.saturated.all()
    assert trace.fault[50]


def test_non_finite_sample_leaves_state_untouched_and_returns_safe_command():
    spec = random_spec(3, n=3, m=2, p=2, q=1, anti_windup="clamp")
    spec["limits"]["u_min"] = [0.5, -2.0]  # zero is outside input 0's range: the safe command clamps it
    spec["limits"]["u_max"] = [2.0, 1.0]
    a = artifact_mod.from_dict(design_spec(parse_spec(spec)).artifact)
    loop = ReferenceLoop(a)
    loop.step([1.0, -1.0], [0.2])
    xh, z = loop.xh.copy(), loop.z.copy()
    for bad_y, bad_r in (([np.nan, 0.0], [0.0]), ([0.0, np.inf], [0.0]), ([0.0, 0.0], [-np.inf])):
        res = loop.step(bad_y, bad_r)
        assert res.fault
        np.testing.assert_array_equal(res.u, [0.5, 0.0])
        np.testing.assert_array_equal(loop.xh, xh)
        np.testing.assert_array_equal(loop.z, z)
    assert not loop.step([0.1, 0.1], [0.0]).fault


def test_clamp_freezes_the_integrator_only_on_saturated_steps():
    spec = parse_spec(random_spec(5, n=2, m=1, p=1, q=1, anti_windup="clamp"))
    a = artifact_mod.from_dict(design_spec(spec).artifact)
    loop = ReferenceLoop(a)
    res = loop.step([50.0], [0.0])  # first step: xh = 0 so v = 0, not saturated: integrates
    assert not res.saturated.any() and loop.z[0] == pytest.approx(-a.Ts * 50.0 * a.Ci[0, 0])
    for _ in range(20):
        z_before = loop.z.copy()
        res = loop.step([50.0], [0.0])
        if res.saturated.any():
            np.testing.assert_array_equal(loop.z, z_before)
            break
    else:
        pytest.fail("the input never saturated")


def test_replay_cli_matches_reference_and_copies_time(example_artifacts, tmp_path):
    a = artifact_mod.load(example_artifacts["quadrotor_lateral"])
    inp, out = tmp_path / "in.csv", tmp_path / "out.csv"
    assert (
        run_cli(
            "simulate",
            example_artifacts["quadrotor_lateral"],
            "--steps",
            "2000",
            "--x0",
            "0.2",
            "0",
            "0",
            "0",
            "--ref",
            "0.5",
            "--noise",
            "0.001",
            "--out",
            inp,
        ).code
        == 0
    )
    r = run_cli("replay", example_artifacts["quadrotor_lateral"], "--input", inp, "--output", out)
    assert r.code == 0, r.err
    rows = np.genfromtxt(out, delimiter=",", names=True)
    samples = read_samples(inp, a)
    trace = ReferenceLoop(a).run(samples.Y, samples.R)
    np.testing.assert_array_equal(rows["t"], samples.t)
    np.testing.assert_array_equal(rows["u0"], trace.u[:, 0])
    np.testing.assert_array_equal(rows["xh3"], trace.xh[:, 3])
    assert set(rows.dtype.names) >= {"u0", "sat0", "fault", "xh0", "xh3", "z0"}
    # the simulated loop tracks the 0.5 m lateral reference
    assert samples.Y[-1, 1] == pytest.approx(0.5, abs=0.02)


def test_replay_compare_checks_both_files_one_step_at_a_time(example_artifacts, tmp_path):
    art = example_artifacts["pendulum"]
    inp, ref, again, bent = (tmp_path / f for f in ("in.csv", "ref.csv", "again.csv", "bent.csv"))
    assert run_cli("simulate", art, "--steps", "300", "--x0", "0", "0", "0.1", "0", "--out", inp).code == 0
    assert run_cli("replay", art, "--input", inp, "--output", ref).code == 0
    res = run_cli("replay", art, "--input", inp, "--output", again, "--compare", ref)
    assert res.code == 0 and "max |du| = 0 " in res.out
    assert res.out.count("one-step check of") == 2 and "FAIL" not in res.out
    lines = ref.read_text().splitlines()
    cells = lines[5].split(",")  # step 4 (line 0 is the header); cells: t, u0, ...
    cells[1] = repr(float(cells[1]) + 0.01 * 40.0)  # 1% of the pendulum's 40 N limit span on one step
    lines[5] = ",".join(cells)
    bent.write_text("\n".join(lines) + "\n")
    res = assert_refused(("replay", art, "--input", inp, "--output", again, "--compare", bent), "step 4: u0 of ")
    assert str(bent) in res.err  # a failed check, not a refusal: the replay's output is written
    assert "0.01 of the limit span" in res.out  # the open-loop difference is printed as information


def test_replay_compare_counts_steps_with_a_differing_saturation_flag_not_flags(example_artifacts, tmp_path):
    """Two inputs (Wood-Berry): the comparison file's flags of both inputs flipped on steps 10-19 and the
    steam flag alone on 30-34. Flags differ on 15 steps of the run (reflux 10, steam 15): the line says
    "15 of N steps" (was 25, per flag, and could exceed N)."""
    art = example_artifacts["wood_berry"]
    inp, ref, other = tmp_path / "in.csv", tmp_path / "ref.csv", tmp_path / "other.csv"
    assert run_cli("simulate", art, "--steps", "60", "--out", inp).code == 0
    assert run_cli("replay", art, "--input", inp, "--output", ref).code == 0
    lines = ref.read_text().splitlines()
    head = lines[0].split(",")
    for k, cols in [(k, ("sat0", "sat1")) for k in range(10, 20)] + [(k, ("sat1",)) for k in range(30, 35)]:
        cells = lines[k + 1].split(",")
        for c in cols:
            cells[head.index(c)] = str(1 - int(cells[head.index(c)]))
        lines[k + 1] = ",".join(cells)
    other.write_text("\n".join(lines) + "\n")
    res = run_cli("replay", art, "--input", inp, "--output", tmp_path / "again.csv", "--compare", other)
    assert "saturation flags differ on 15 (per input: reflux 10, steam 15), fault flags on 0 of 60 steps" in res.out
    from gainlink.proof.replay_io import compare_traces, read_trace

    a = artifact_mod.load(art)
    c = compare_traces(a, read_trace(ref, a), read_trace(other, a))
    assert (c.sat_mismatches, c.sat_mismatches_per_input, c.steps) == (15, (10, 15), 60)


def test_the_compiled_step_is_shared_by_equal_laws_and_never_by_laws_that_differ_in_one_gain():
    """The law's step is compiled once per law (keyed by what it is written from): a copy of an artifact shares it,
    one gain changed in its twelfth digit gets its own."""
    from gainlink.proof.reference_step import compile_reference_step

    a = artifact_mod.from_dict(design_spec(parse_spec(random_spec(7, **CASES[2]))).artifact)
    same = artifact_mod.from_dict(dict(a.data))
    data = dict(a.data)
    data["K"] = [list(row) for row in data["K"]]
    data["K"][0][0] *= 1.0 + 1e-12
    other = artifact_mod.from_dict(artifact_mod.seal({k: v for k, v in data.items() if k != "sha256"}))
    assert compile_reference_step(same) is compile_reference_step(a)
    assert compile_reference_step(other) is not compile_reference_step(a)
    y, r = (a.y_op + 0.3).tolist(), (a.r_op + 0.1).tolist()
    xh = [1.0] * a.n
    assert (
        compile_reference_step(other)(xh, a.z0.tolist(), y, r)[1]
        != compile_reference_step(a)(xh, a.z0.tolist(), y, r)[1]
    )
