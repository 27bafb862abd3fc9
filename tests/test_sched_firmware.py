"""The scheduled law in C (firmware/src/gl_sched.c): its export, its float32 model against the float64 reference,
and the host build against the model bit for bit with sigma moving across the whole envelope (held on a
non-finite sigma, clipped outside it, rate-limited, filtered)."""

from __future__ import annotations

import itertools
import re
import tomllib

import numpy as np
import pytest
from gainlink.laws import design as design_spec
from gainlink.laws.scheduled.codegen import tables
from gainlink.laws.scheduled.model import ScheduledFloat32Loop
from gainlink.laws.scheduled.native import NativeScheduledLoop
from gainlink.laws.scheduled.reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE, ScheduledLoop
from gainlink.shipping import codegen
from gainlink.shipping.artifact import from_dict, load
from gainlink.shipping.export_c import render_export
from gainlink.spec import parse_spec
from schedule_cases import external_tank, tank_dict
from support.cli import GOOD_SPEC, assert_refused, run_cli
from support.designs import designed

# One worker runs this module (make test: --dist loadgroup): the scheduled builds, made once.
pytestmark = pytest.mark.xdist_group("test_sched_firmware")

FLOAT = r"-?\d+(?:\.\d*)?(?:e[-+]?\d+)?f"


@pytest.fixture(scope="module")
def level_data():
    """The example tank's artifact dict, scheduled on its measured level (predictor form, no filter, no rate
    limit)."""
    return designed(tank_dict())


@pytest.fixture(scope="module")
def level(level_data):
    """The example tank's artifact."""
    return from_dict(level_data)


@pytest.fixture(scope="module")
def external_data():
    """The tank scheduled on an external signal, current form, sigma filtered (tau 0.1 s) and rate-limited (4/s):
    its artifact dict."""
    return designed(external_tank(form="current", rate_max=4.0, filter_tau=0.1))


@pytest.fixture(scope="module")
def external(external_data):
    """That artifact."""
    return from_dict(external_data)


def _samples(a, N: int = 600):
    """A closed loop of the float64 law around the nonlinear tank (``examples/tank_scheduled.toml``), recorded for
    open-loop replay: the reference sweeps the level below, across and above the envelope (sigma, the level or an
    external copy of it, moves across all of it and is clipped at both ends), a reference jump saturates the pump,
    one sample is refused; an external sigma also jumps faster than its rate limit and is NaN or inf on three
    samples."""
    rng = np.random.default_rng(7)
    t = np.arange(N) * a.Ts
    ref = 0.02 + 1.2 * (1 - np.abs(1 - 2 * np.arange(N) / N))  # a triangle from 0.02 up to 1.22 and back
    ref[N // 2 - 60 : N // 2 - 40] = 0.05  # a jump down and back up: the pump saturates
    law = ScheduledLoop(a)
    q, h = 0.08, 0.04
    Y, R, S = np.zeros((N, 1)), ref.reshape(N, 1), np.zeros((N, 1))
    for k in range(N):
        Y[k, 0] = np.nan if k == 150 else h + 0.002 * rng.standard_normal()
        S[k, 0] = h + (0.6 if (t[k] // 3.0) % 3 == 1 else 0.0)  # external sigma: the level with jumps
        if k in (200, 201, 202):
            S[k, 0] = (np.nan, np.inf, -np.inf)[k - 200]
        u = float(law.step(Y[k], R[k], S[k] if a.schedule.external else None).u[0])
        for _ in range(10):  # the nonlinear tank, Euler at Ts / 10
            q, h = q + a.Ts / 10 * (u - q) / 0.1, max(h + a.Ts / 10 * (q - 0.4 * np.sqrt(max(h, 0.0))), 0.0)
    return Y, R, (S if a.schedule.external else None)


def _bits(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, dtype=np.float64).view(np.uint64)


def test_scheduled_export_holds_the_tables_and_an_unscheduled_one_is_unchanged(level, external):
    """The export of a schema-2 artifact: gl_gains.h with the macros of the scheduled loop, gl_sched_gains.c with
    every per-point coefficient as its float32 value, and the files gl_law.h reads for every law (flags, record,
    parameter table); same artifact, same bytes. An unscheduled artifact's export holds codegen.render_c's files,
    byte for byte."""
    files = render_export(external)
    law_files = ["gl_flags.h", "gl_law_params.h", "gl_record_scheduled_float32.h"]
    assert sorted(files) == sorted(["gl_gains.h", "gl_sched_gains.c", *law_files]) and files == render_export(external)
    h = files["gl_gains.h"]
    for macro in ("GL_SCHEDULED 1", "GL_NPTS 3", "GL_E 1", "GL_SIGMA_EXTERNAL 1", "GL_SIGMA_INDEX 0",
                  "GL_SIGMA_FILTERED 1", "GL_SIGMA_RATE_LIMITED 1", "GL_OBSERVER_FORM 1"):  # fmt: skip
        assert f"#define {macro}" in h
    assert "#define GL_E 0" in render_export(level)["gl_gains.h"]
    assert "#define GL_SIGMA_RATE_LIMITED 0" in render_export(level)["gl_gains.h"]
    src = files["gl_sched_gains.c"]
    t = tables(external)
    S = external.schedule
    for name in ("Kx", "Ky", "Kz", "F", "G", "Ly"):
        block = re.search(rf"\.{name} = \{{(.*?)\n +\}},", src, re.S).group(1)
        got = np.array([float(v[:-1]) for v in re.findall(FLOAT, block)], dtype=np.float32)
        want = S.coef[name].reshape(-1).astype(np.float32)
        assert np.array_equal(got, want) and np.array_equal(t[name].reshape(-1), want), name
    assert float(t["rate_step"]) == np.float32(external.Ts * 4.0)
    assert float(t["alpha"]) == np.float32(-np.expm1(-external.Ts / 0.1))
    plain = from_dict(design_spec(parse_spec(tomllib.loads(GOOD_SPEC))).artifact)
    assert {k: v for k, v in render_export(plain).items() if k in codegen.render_c(plain)} == codegen.render_c(plain)


def test_export_cli_writes_the_scheduled_tables(level_data, tmp_path):
    from gainlink.shipping import artifact as artifact_mod

    path = tmp_path / "gains.json"
    artifact_mod.write(path, level_data)
    res = run_cli("export", path, "--out", tmp_path / "out")
    assert res.code == 0, res.err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(render_export(load(path)))


@pytest.mark.parametrize("case", ["level", "external"])
def test_float32_model_is_close_to_the_float64_law(case, request):
    """The float32 model of the C follows the float64 reference: same flags and faults, commands and states within
    float32 rounding of the command's span."""
    a = request.getfixturevalue(case)
    Y, R, S = _samples(a)
    ref = ScheduledLoop(a).run(Y, R, S)
    f32 = ScheduledFloat32Loop(a).run(Y, R, S)
    assert np.array_equal(ref.fault, f32.fault) and np.array_equal(ref.sigma_flags, f32.sigma_flags)
    assert np.array_equal(ref.saturated, f32.saturated)
    assert np.max(np.abs(ref.u - f32.u)) < 1e-5 * float(a.u_max[0] - a.u_min[0])
    assert np.max(np.abs(ref.sigma - f32.sigma)) < 1e-6
    assert np.max(np.abs(ref.state - f32.state)) < 1e-5


@pytest.mark.parametrize("case", ["level", "external"])
def test_host_c_is_the_float32_model_bit_for_bit(case, request):
    """The host build of gl_sched.c and the numpy model agree bit for bit on every command, flag and state, with
    sigma sweeping the whole envelope (every interval, both ends clipped), held on NaN and inf, rate-limited and
    filtered (external), and a refused sample leaving the state untouched."""
    a = request.getfixturevalue(case)
    Y, R, S = _samples(a)
    c = NativeScheduledLoop(a).run(Y, R, S)
    m = ScheduledFloat32Loop(a).run(Y, R, S)
    for name in ("u", "sigma", "state"):
        assert np.array_equal(_bits(getattr(c, name)), _bits(getattr(m, name))), name
    for name in ("saturated", "fault", "sigma_flags"):
        assert np.array_equal(getattr(c, name), getattr(m, name)), name
    pts = a.schedule.points.astype(np.float32)
    assert abs(c.sigma.min() - pts[0]) < 1e-6 and abs(c.sigma.max() - pts[-1]) < 1e-6  # the filter approaches
    assert all(np.any((c.sigma > lo) & (c.sigma < hi)) for lo, hi in itertools.pairwise(pts))
    assert np.any(c.sigma_flags & SIGMA_CLIPPED) and c.saturated.any() and c.fault[150]
    assert np.array_equal(_bits(c.state[150]), _bits(c.state[149]))  # the refused sample changed nothing
    if case == "external":
        assert np.all(c.sigma_flags[200:203] & SIGMA_HELD) and np.any(c.sigma_flags & SIGMA_RATE)
        assert c.sigma[200] == c.sigma[199] == c.sigma[202]
        assert np.max(np.abs(np.diff(c.sigma))) <= np.float32(a.Ts * 4.0) * (1 + 1e-6)


#: Where in an interval sigma is put (lam): every hundredth from end to end and the middle itself, never on a point.
INSIDE = (*np.linspace(0.005, 0.995, 100), 0.5)


def test_start_and_safe_commands_are_u_op_interpolated_where_sigma_is_inside_an_interval(level):
    """The first command after a reset is the start command clamp(u_op(sigma)) (the velocity form starts there: no
    kick), and a refused sample's is the safe command clamp(u_op(sigma held)), with sigma strictly inside every
    interval, a hundredth apart (an interpolation replaced only near the middle of an interval, or only near its
    ends, is seen). Oracle: the points' own trims interpolated linearly in sigma by numpy.interp (the law's
    definition, docs/design.md), in float64 from the float32 sigma the C was given; the C runs float32, so they
    agree to rounding, far closer than the trim's change across a hundredth of an interval."""
    a = level
    points, u_op = a.schedule.points, a.schedule.u_op[:, 0]
    assert np.all(np.diff(u_op) != 0)  # the trim moves across every interval: where sigma is matters

    def trim(sigma: np.float32) -> float:
        return float(np.clip(np.interp(float(sigma), points, u_op), a.u_min[0], a.u_max[0]))

    loop = NativeScheduledLoop(a)
    tol = 1e-6 * float(a.u_max[0] - a.u_min[0])
    for i, lam in itertools.product(range(points.size - 1), INSIDE):
        start = np.float32(points[i] + lam * (points[i + 1] - points[i]))  # sigma is the level: y[0]
        moved = np.float32(points[-2 - i] + (1 - lam) * (points[-1 - i] - points[-2 - i]))  # another interval
        loop.reset()
        # the start at `start` (reference = level: no error), a step to `moved`, then a refused sample
        Y = np.array([[start], [moved], [np.nan]], dtype=np.float32)
        R = np.array([[start], [moved], [moved]], dtype=np.float32)
        c = loop.run(Y, R)
        assert not c.fault[0] and c.sigma[1] == moved and c.fault[2], (i, lam)
        assert abs(c.u[0, 0] - trim(start)) <= tol, (i, lam, c.u[0, 0], trim(start))
        assert abs(c.u[2, 0] - trim(moved)) <= tol, (i, lam, c.u[2, 0], trim(moved))


def test_cortex_m4f_in_qemu_is_the_host_bit_for_bit(external):
    """One replay through the Cortex-M4F image (mps2-an386) in QEMU: every command, flag and state equals the host
    build's bit for bit, with the external sigma moving across the envelope, held, clipped and rate-limited."""
    from gainlink.laws.scheduled import qemu as sched_qemu

    Y, R, S = _samples(external)
    host = NativeScheduledLoop(external).run(Y, R, S)
    m4 = sched_qemu.run(external, Y, R, S)
    for name in ("u", "sigma", "state"):
        assert np.array_equal(_bits(getattr(m4, name)), _bits(getattr(host, name))), name
    for name in ("saturated", "fault", "sigma_flags"):
        assert np.array_equal(getattr(m4, name), getattr(host, name)), name
    flags = np.bitwise_or.reduce(m4.sigma_flags)
    assert flags == SIGMA_HELD | SIGMA_CLIPPED | SIGMA_RATE and m4.fault.sum() == 1


def test_replay_cli_runs_the_scheduled_c_on_host_and_qemu(external_data, external, tmp_path):
    """``gainlink replay --engine native|qemu`` on a scheduled artifact with s0: both write the output of the
    float32 model, byte for byte (the same CSV text, which names its arithmetic, float32); an engine flag that does
    not apply is one line, exit 2."""
    from gainlink.laws.scheduled.replay import format_trace
    from gainlink.shipping import artifact as artifact_mod

    path, inp = tmp_path / "gains.json", tmp_path / "in.csv"
    artifact_mod.write(path, external_data)
    Y, R, S = _samples(external, N=300)
    rows = ["y0,r0,s0"] + [",".join(repr(float(v)) for v in (Y[k, 0], R[k, 0], S[k, 0])) for k in range(len(Y))]
    inp.write_text("\n".join(rows) + "\n")
    want = format_trace(external, ScheduledFloat32Loop(external).run(Y, R, S), numeric="float32")
    for engine in ("native", "qemu"):
        out = tmp_path / f"{engine}.csv"
        res = run_cli("replay", path, "--input", inp, "--output", out, "--engine", engine)
        assert res.code == 0, res.err
        assert out.read_text() == want, engine
    ref = tmp_path / "ref.csv"
    assert run_cli("replay", path, "--input", inp, "--output", ref).code == 0
    res = run_cli("replay", path, "--input", inp, "--output", tmp_path / "c.csv", "--engine", "native",
                  "--compare", ref)  # fmt: skip
    assert res.code == 0, res.err
    assert "native (the C's float32 arithmetic, bit for bit, from its own state at each step): pass," in res.out
    argv = (
        "replay",
        path,
        "--input",
        inp,
        "--output",
        tmp_path / "x.csv",
        "--engine",
        "native",
        "--target",
        "cortex-m4",
    )
    assert_refused(argv, "--target", tmp_path)


def test_firmware_commands_on_a_scheduled_artifact(external_data, external, tmp_path):
    """``firmware build --target host`` ships the scheduled loop's libraries; ``firmware run --input`` replays a CSV
    (outputs, references, the external signals) through the one host executable (``gainlink_loop_host`` on the
    scheduled law) and writes what ``replay --engine native`` writes, bit for bit; ``pil run`` without the external
    sigma's signal is refused in one line, exit 2 (it runs the scheduled image: test_sched_pil)."""
    from gainlink.shipping import artifact as artifact_mod

    path = tmp_path / "gains.json"
    artifact_mod.write(path, external_data)
    res = run_cli("firmware", "build", path, "--target", "host", "--out", tmp_path / "fw")
    assert res.code == 0, res.err
    shipped = {p.name for p in (tmp_path / "fw").iterdir()}
    assert {"libgainlink_host.so", "libgainlink_loop.a", "firmware.json"} <= shipped
    Y, R, S = _samples(external, 260)  # a refused sample (150), a non-finite sigma (200-202)
    lines = ["t,y0,r0,s0"] + [",".join(repr(float(v)) for v in (k * external.Ts, Y[k, 0], R[k, 0], S[k, 0]))
                              for k in range(Y.shape[0])]  # fmt: skip
    (tmp_path / "in.csv").write_text("\n".join(lines) + "\n")
    res = run_cli("firmware", "run", path, "--input", tmp_path / "in.csv", "--output", tmp_path / "fw.csv")
    assert res.code == 0, res.err
    res = run_cli("replay", path, "--input", tmp_path / "in.csv", "--engine", "native", "--output",
                  tmp_path / "native.csv")  # fmt: skip
    assert res.code == 0, res.err
    assert (tmp_path / "fw.csv").read_text() == (tmp_path / "native.csv").read_text()
    assert_refused(("pil", "run", path, "--steps", "5"), "scheduled on load", tmp_path)
