"""The C loop on the host (ctypes, one call per block) against the float64 reference, plus its guards.

Tolerance. The C loop runs in float32 and the reference in float64. Each gain is rounded once to
float32 (relative 6e-8) and every step rounds each multiply-add once (explicit fmaf); the observer and
integrator carry these errors forward through dynamics whose spectral radius is at most ~0.99, i.e.
amplified by at most ~1/(1 - 0.99) = 100 over rows of up to n + m + p = 20 terms: 6e-8 * 20 * 100 ~ 1e-4
relative to the size of the signal. RTOL = 1e-4 of each signal's largest magnitude over the replay is
that bound; what we measure is 1e-7..1e-5. A wrong sign, index or term gives errors of order 1.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from gainlink.engines.native import NativeLoop
from gainlink.firmware.build import build
from gainlink.laws.lq.golden import random_cases
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping.artifact import from_dict, seal
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from support.designs import golden_examples

RTOL = 1e-4
FORMS, MODES = ("predictor", "current"), ("none", "clamp", "backcalc")
RANDOM_DESIGNS = 12  # conftest's random_designs; the matrix runs the other 18 of golden.random_cases(30)
GL_OK, GL_SATURATED, GL_ERR_NANINF, GL_ERR_CRC, GL_ERR_DIMS, GL_ERR_RANGE, GL_ERR_WATCHDOG, GL_ERR_BUSY = (
    0,
    1,
    -2,
    -3,
    -4,
    -5,
    -6,
    -7,
)


pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def assert_matches_reference(trace, expected, artifact, label):
    for name in ("u", "xh", "z"):
        got, want = getattr(trace, name), getattr(expected, name)
        if want.size == 0:
            continue
        scale = max(float(np.max(np.abs(want))), 1e-9)
        err = float(np.max(np.abs(got - want))) / scale
        assert err <= RTOL, f"{label}: {name} differs from the reference by {err:.2e} relative (> {RTOL})"
    # saturation flags agree except where the reference command sits on a limit within the tolerance
    scale = max(float(np.max(np.abs(expected.u))), 1e-9)
    near = np.minimum(np.abs(expected.u - artifact.u_min), np.abs(expected.u - artifact.u_max)) <= RTOL * scale
    unsat_near = np.abs(expected.u - np.clip(expected.u, artifact.u_min, artifact.u_max)) <= RTOL * scale
    assert np.all((trace.saturated == expected.saturated) | (near & unsat_near)), f"{label}: saturation flags differ"
    assert np.array_equal(trace.fault, expected.fault), f"{label}: fault flags differ"


def test_examples_match_reference():
    for case in golden_examples():
        trace = NativeLoop(case.artifact).run(case.Y, case.R)
        assert case.expected.saturated.any(), f"{case.label}: golden samples should saturate"
        assert_matches_reference(trace, case.expected, case.artifact, case.label)


def test_random_designs_cover_every_form_and_size(random_designs):
    cases = random_designs
    assert len(cases) == RANDOM_DESIGNS
    forms = {(c.artifact.observer_form, c.artifact.anti_windup) for c in cases}
    assert len(forms) == 6, "every observer form x anti-windup mode is covered"
    assert max(c.artifact.n for c in cases) == 12 and max(c.artifact.m for c in cases) <= 4
    assert any(c.artifact.q > 0 for c in cases) and any(c.artifact.q == 0 for c in cases)
    assert any(np.any(c.artifact.Dd != 0) for c in cases), "feed-through (G = Bd - L Dd) is exercised"
    about_op = {(c.artifact.observer_form, c.artifact.anti_windup) for c in cases if c.artifact.has_operating_point}
    assert about_op == forms, "every form and mode also about a non-zero operating point"


@pytest.mark.parametrize("index", range(RANDOM_DESIGNS))  # one test each: the workers build them in parallel
def test_random_design_matches_reference(random_designs, index):
    assert_case_matches_reference(random_designs[index])


@pytest.mark.matrix
@pytest.mark.parametrize("index", range(RANDOM_DESIGNS, 30))
def test_more_random_designs_match_reference(index):
    assert_case_matches_reference(random_cases(30)[index])


def assert_case_matches_reference(case) -> None:
    assert case.expected.saturated.any(), f"{case.label}: golden samples should saturate"
    trace = NativeLoop(case.artifact).run(case.Y, case.R)
    assert_matches_reference(trace, case.expected, case.artifact, case.label)


def test_generated_unrolled_step_is_bit_identical_to_generic_loops(random_designs):
    """gl_step.h (generated, unrolled) and the library's generic loops perform the same operations."""
    picked = {}
    for case in random_designs:
        picked.setdefault((case.artifact.observer_form, case.artifact.anti_windup), case)
    for case in picked.values():
        generic = build(case.artifact, target="host", options={"GL_STEP_UNROLLED": "OFF"}, only="gainlink_host").files[
            "shared"
        ]
        a = NativeLoop(case.artifact).run_raw(case.Y, case.R)
        b = NativeLoop(case.artifact, library=generic).run_raw(case.Y, case.R)
        for key in a:
            assert np.array_equal(a[key].view(np.uint8), b[key].view(np.uint8)), f"{case.label}: {key}"


@pytest.fixture(scope="module")
def pendulum():
    return golden_examples()[0]


def test_nan_sample_leaves_state_untouched_and_returns_safe_command(pendulum):
    a = pendulum.artifact
    loop = NativeLoop(a)
    Y, R = pendulum.Y[:50].copy(), pendulum.R[:50].copy()
    Y[20, 1] = np.nan
    R[30, 0] = np.inf
    raw = loop.run_raw(Y, R)
    safe = np.clip(np.zeros(a.m), a.u_min, a.u_max)
    for k in (20, 30):
        assert raw["fault"][k] == 1 and raw["sat"][k] == 0
        assert np.array_equal(raw["u"][k], safe.astype(np.float32))
        assert np.array_equal(raw["xh"][k], raw["xh"][k - 1]) and np.array_equal(raw["z"][k], raw["z"][k - 1])
    assert raw["fault"].sum() == 2 and np.all(np.isfinite(raw["xh"]))
    # the whole run equals the reference fed the same samples (which refuses the same two)
    expected = ReferenceLoop(a).run(Y, R)
    from gainlink.engines.native import trace_from_raw

    assert_matches_reference(trace_from_raw(raw, m=a.m), expected, a, "nan")


def test_watchdog_holds_then_gives_safe_command(pendulum):
    a = pendulum.artifact
    loop = NativeLoop(a, watchdog_periods=5)
    last = None
    for k in range(40):
        last = loop.step(pendulum.Y[k], pendulum.R[k])
    assert last.status in (GL_OK, GL_SATURATED)
    held = [loop.idle() for _ in range(4)]
    assert all(h.status == GL_OK and np.array_equal(h.u, last.u) for h in held), "holds the last command"
    expired = loop.idle()
    assert expired.status == GL_ERR_WATCHDOG
    assert np.array_equal(expired.u, np.clip(np.zeros(a.m), a.u_min, a.u_max).astype(np.float32))
    assert loop.idle().status == GL_ERR_WATCHDOG, "stays expired until a measurement arrives"
    assert loop.step(pendulum.Y[40], pendulum.R[40]).status in (GL_OK, GL_SATURATED)
    assert loop.idle().status == GL_OK, "a measurement re-arms the watchdog"


def test_gain_update_rejections_leave_running_set_untouched(pendulum):
    a = pendulum.artifact
    loop, twin = NativeLoop(a), NativeLoop(a)
    crc0 = loop.active_crc32()
    g = loop.default_gains()
    assert loop.crc32(g) == g.crc32 == crc0

    bad_crc = loop.default_gains()
    bad_crc.K[0][1] += 1.0  # edited but not re-sealed
    assert loop.stage(bad_crc) == GL_ERR_CRC

    wrong_dims = loop.default_gains()
    wrong_dims.n = a.n + 1
    wrong_dims.crc32 = loop.crc32(wrong_dims)
    assert loop.stage(wrong_dims) == GL_ERR_DIMS

    nan_gain = loop.default_gains()
    nan_gain.L[2][0] = float("nan")
    nan_gain.crc32 = loop.crc32(nan_gain)
    assert loop.stage(nan_gain) == GL_ERR_NANINF

    bad_limits = loop.default_gains()
    bad_limits.u_min[0], bad_limits.u_max[0] = 1.0, -1.0
    bad_limits.crc32 = loop.crc32(bad_limits)
    assert loop.stage(bad_limits) == GL_ERR_RANGE

    a1 = loop.run_raw(pendulum.Y, pendulum.R)
    b1 = twin.run_raw(pendulum.Y, pendulum.R)
    assert loop.active_crc32() == crc0
    for key in a1:
        assert np.array_equal(a1[key], b1[key]), "rejected updates must not change anything"


def test_gain_update_is_staged_checked_and_swapped_between_steps(pendulum):
    a = pendulum.artifact
    loop = NativeLoop(a)
    Y, R = pendulum.Y, pendulum.R
    first = loop.run_raw(Y[:100], R[:100])
    new = loop.default_gains()
    new.K[0][2] *= 1.1
    new.Ki[0][0] *= 0.9
    new.crc32 = loop.crc32(new)
    assert loop.stage(new) == GL_OK
    assert loop.stage(new) == GL_ERR_BUSY, "only one update can wait"
    assert loop.active_crc32() != new.crc32, "not applied before the next step"
    rest = loop.run_raw(Y[100:], R[100:])
    assert loop.active_crc32() == new.crc32
    # expected: the reference with the new gains (artifact rebuilt from the edited numbers), continued
    # from the state the C loop had when the swap happened
    data = dict(a.data)
    K = np.array(a.K)
    K[0, 2] = float(np.float32(float(np.float32(a.K[0, 2])) * 1.1))  # what ctypes stored
    Ki = np.array(a.Ki)
    Ki[0, 0] = float(np.float32(float(np.float32(a.Ki[0, 0])) * 0.9))
    data["K"], data["Ki"] = K.tolist(), Ki.tolist()
    data["Kaw"] = a.Kaw.tolist()
    changed = from_dict(seal(data))
    ref = ReferenceLoop(changed)
    ref.xh, ref.z = first["xh"][-1].astype(float), first["z"][-1].astype(float)
    expected = ref.run(Y[100:], R[100:])
    from gainlink.engines.native import trace_from_raw

    assert_matches_reference(trace_from_raw(rest, m=a.m), expected, changed, "after swap")
    old = ReferenceLoop(a)
    old.xh, old.z = first["xh"][-1].astype(float), first["z"][-1].astype(float)
    assert np.max(np.abs(old.run(Y[100:], R[100:]).u - rest["u"])) > 1e-3, "the new gains are really in use"


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_property_commands_within_limits_and_finite(pendulum, data):
    """For any finite samples, |u| stays within the limits and nothing non-finite appears."""
    a = pendulum.artifact
    N = data.draw(st.integers(min_value=1, max_value=40))
    finite = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False, width=32)
    Y = data.draw(hnp.arrays(np.float32, (N, a.p), elements=finite))
    R = data.draw(hnp.arrays(np.float32, (N, a.q), elements=finite))
    raw = _property_loop(a).run_raw(Y, R)
    assert np.all(raw["u"] >= a.u_min.astype(np.float32)) and np.all(raw["u"] <= a.u_max.astype(np.float32))
    assert np.all(np.isfinite(raw["u"])) and np.all(np.isfinite(raw["xh"])) and np.all(np.isfinite(raw["z"]))
    assert not raw["fault"].any()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_property_non_finite_samples_never_propagate(pendulum, data):
    """Any mix of finite and NaN/Inf samples: refused exactly where non-finite, state and commands stay finite."""
    a = pendulum.artifact
    N = data.draw(st.integers(min_value=1, max_value=40))
    anything = st.floats(width=32) | st.sampled_from([np.nan, np.inf, -np.inf])
    Y = data.draw(hnp.arrays(np.float32, (N, a.p), elements=anything))
    R = data.draw(hnp.arrays(np.float32, (N, a.q), elements=anything))
    with np.errstate(invalid="ignore"):  # keep finite samples within a physical range, NaN/Inf as drawn
        Y = np.where(np.isfinite(Y) & (np.abs(Y) > 1e4), np.sign(Y) * 1e4, Y).astype(np.float32)
        R = np.where(np.isfinite(R) & (np.abs(R) > 1e4), np.sign(R) * 1e4, R).astype(np.float32)
    bad = ~(np.isfinite(Y).all(axis=1) & np.isfinite(R).all(axis=1))
    raw = _property_loop(a).run_raw(Y, R)
    assert np.array_equal(raw["fault"].astype(bool), bad)
    assert np.all(np.isfinite(raw["u"])) and np.all(np.isfinite(raw["xh"])) and np.all(np.isfinite(raw["z"]))
    assert np.all(raw["u"] >= a.u_min.astype(np.float32)) and np.all(raw["u"] <= a.u_max.astype(np.float32))


_PROPERTY_LOOPS: dict[str, NativeLoop] = {}


def _property_loop(a) -> NativeLoop:
    if a.sha256 not in _PROPERTY_LOOPS:
        _PROPERTY_LOOPS[a.sha256] = NativeLoop(a)
    loop = _PROPERTY_LOOPS[a.sha256]
    loop.reset()
    return loop


def _sanitized_cases(pendulum, random_designs):
    picked = {("pendulum",): pendulum}
    for case in random_designs:
        picked.setdefault((case.artifact.observer_form, case.artifact.anti_windup, case.artifact.q > 0), case)
    return list(picked.values())


@pytest.mark.parametrize("share", range(3))  # the variants in three shares, built on three workers
@pytest.mark.slow
def test_host_executable_under_asan_ubsan_matches_ctypes(pendulum, random_designs, share):
    """Built with -fsanitize=address,undefined for every compiled variant (forms, anti-windup modes, with and
    without integrators), the loop executable runs clean and agrees with the ctypes library bit for bit."""
    variants = _sanitized_cases(pendulum, random_designs)
    structures = {(c.artifact.observer_form, c.artifact.anti_windup, c.artifact.q > 0) for c in variants}
    assert {(f, m) for f, m, _ in structures} == {(f, m) for f in FORMS for m in MODES} and len(variants) >= 7
    for case in variants[share::3]:
        a = case.artifact
        exe = build(a, target="host", options={"GL_SANITIZE": "ON"}, only="gainlink_loop_host").files["exe"]
        N = 120
        Y, R = case.Y[:N].copy(), case.R[:N]
        Y[50, 0] = np.nan
        lines = [" ".join(repr(float(v)) for v in np.concatenate([Y[k], R[k]])) for k in range(N)]
        script = lines[:60] + ["idle", "stage", "crc"] + lines[60:] + ["reset", "bogus line"]
        proc = subprocess.run([str(exe)], input="\n".join(script) + "\n", capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr  # the malformed last line
        assert "runtime error" not in proc.stderr and "AddressSanitizer" not in proc.stderr, proc.stderr
        out = proc.stdout.splitlines()
        assert out[0].startswith(f"gainlink-loop {a.name} sha256:{a.sha256}")
        # each step: status flags sat u (m), xh (n), z (q)
        steps = [line.split() for line in out[1:] if line.startswith("step ")]
        assert len(steps) == N
        raw = NativeLoop(a).run_raw(Y, R)
        u = np.array([[float(v) for v in s[4 : 4 + a.m]] for s in steps], dtype=np.float32)
        xh = np.array([[float(v) for v in s[4 + a.m : 4 + a.m + a.n]] for s in steps], dtype=np.float32)
        z = np.array([[float(v) for v in s[4 + a.m + a.n :]] for s in steps], dtype=np.float32).reshape(N, a.q)
        assert np.array_equal(u, raw["u"]) and np.array_equal(xh, raw["xh"]) and np.array_equal(z, raw["z"]), case.label
        assert int(steps[50][1]) == GL_ERR_NANINF and int(steps[50][2]) == 1  # the status and the fault flag
        assert any(line.startswith("error ") for line in out), "a malformed line is answered, not fatal"


@pytest.mark.slow
def test_golden_script_writes_files_the_c_loop_replays(tmp_path):
    """scripts/gen_golden.py writes artifacts + reference answers; the C loop replays them within RTOL."""
    import json
    import runpy

    from gainlink.proof.reference import Trace
    from gainlink.shipping.artifact import load

    script = Path(__file__).resolve().parents[1] / "scripts" / "gen_golden.py"
    # six random designs (the first six of the thirty the other tests replay): the script, not the designs, is
    # under test here, and thirty cost a worker that has not drawn them 20 s of CPU
    assert runpy.run_path(str(script))["main"](["--out", str(tmp_path), "--random", "6"]) == 0
    index = json.loads((tmp_path / "index.json").read_text())
    assert len(index) == 9 and all(c["saturated_steps"] > 0 for c in index)
    for entry in index[:3] + index[-3:]:
        art = load(tmp_path / f"{entry['label']}.gains.json")
        gold = np.load(tmp_path / f"{entry['label']}.npz")
        expected = Trace(u=gold["u"], saturated=gold["saturated"], xh=gold["xh"], z=gold["z"], fault=gold["fault"])
        assert_matches_reference(NativeLoop(art).run(gold["Y"], gold["R"]), expected, art, entry["label"])


def _children(pid: int) -> list[int]:
    return [int(c) for t in Path(f"/proc/{pid}/task").iterdir() for c in (t / "children").read_text().split()]


def test_a_sigterm_to_firmware_run_stops_the_loop_it_started_and_leaves_nothing_running(pend):
    """`gainlink firmware run` hands its stdin/stdout to the host loop; a SIGTERM sent to the command alone (a
    supervisor, `kill PID`) reaches the loop too, and the command exits 0 (asked to stop, it did)."""
    import os
    import signal
    import sys

    exe = str(Path(sys.executable).with_name("gainlink"))
    proc = subprocess.Popen(
        [exe, "firmware", "run", str(pend)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    loop = None
    try:
        assert proc.stdout.readline().startswith(b"gainlink-loop pendulum ")  # the loop is up; its stdin stays open
        (loop,) = _children(proc.pid)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        assert not Path(f"/proc/{loop}").exists()  # stopped and reaped, not left reading a pipe nobody closes
    finally:
        for pid in (proc.pid, loop):  # on a failure, neither is left behind
            if pid is not None and Path(f"/proc/{pid}").exists():
                os.kill(pid, signal.SIGKILL)
        proc.wait()
        for f in (proc.stdin, proc.stdout, proc.stderr):
            f.close()


def test_firmware_run_answers_each_stdin_line_and_exits_2_after_an_unreadable_one(pend):
    """The stdin protocol of `gainlink firmware run` (its help): numbers separated by spaces, tabs or commas, each
    line answered by one; a line it cannot read is answered `error ...` and the loop goes on, but the exit status
    is then 2, with one line on stderr."""
    import sys

    from gainlink.laws.lq.model import Float32Loop
    from gainlink.shipping import records
    from gainlink.shipping.artifact import load

    a = load(pend)
    rng = np.random.default_rng(3)
    Y, R = rng.normal(0.0, 0.05, (3, a.p)), np.full((3, a.q), 0.2)
    rows = [np.concatenate([Y[k], R[k]]).astype(np.float32) for k in range(3)]
    script = [",".join(repr(float(v)) for v in rows[0]), "y0,y1,r0", "\t".join(repr(float(v)) for v in rows[1])]
    script.append(" , ".join(repr(float(v)) for v in rows[2]))
    exe = str(Path(sys.executable).with_name("gainlink"))
    proc = subprocess.run(
        [exe, "firmware", "run", str(pend)], input="\n".join(script) + "\n", capture_output=True, text=True
    )
    answers = proc.stdout.splitlines()[1:]
    assert len(answers) == len(script)
    assert answers[1] == f"error expected {a.p + a.q} numbers, idle, reset, stage or crc"
    want = Float32Loop(a).run(np.array(rows)[:, : a.p].astype(float), np.array(rows)[:, a.p :].astype(float)).u
    recs = records.layout(a).from_text([answers[k].split()[1:] for k in (0, 2, 3)])  # the step lines' records
    got = records.column(recs, "u").reshape(3, a.m)
    assert np.array_equal(got, want.astype(np.float32))  # the refused line changed nothing
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == ["gainlink_loop_host: 1 of 4 input lines unreadable (the first: line 2)"]


def test_firmware_run_replays_a_csv_through_the_host_executable(tmp_path, pendulum):
    import sys

    from gainlink.shipping.artifact import render

    a = pendulum.artifact
    art = tmp_path / "gains.json"
    art.write_text(render(a.data))
    Y, R = pendulum.Y[:100].copy(), pendulum.R[:100]
    Y[7, 1] = np.inf
    rows = ["y0,y1,r0"] + [",".join(repr(float(v)) for v in np.concatenate([Y[k], R[k]])) for k in range(100)]
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    exe = str(Path(sys.executable).with_name("gainlink"))
    for engine_args, name in (
        (["firmware", "run", str(art), "--input", str(tmp_path / "in.csv"), "--output"], "run"),
        (["replay", str(art), "--input", str(tmp_path / "in.csv"), "--engine", "native", "--output"], "native"),
    ):
        proc = subprocess.run([exe, *engine_args, str(tmp_path / f"{name}.csv")], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
    run_rows = (tmp_path / "run.csv").read_text().splitlines()
    native_rows = (tmp_path / "native.csv").read_text().splitlines()
    assert run_rows[0] == native_rows[0]
    # the executable prints %.9g (round-trip float32), replay prints the float32 value's repr: same numbers
    got = np.array([[float(v) for v in r.split(",")] for r in run_rows[1:]], dtype=np.float32)
    want = np.array([[float(v) for v in r.split(",")] for r in native_rows[1:]], dtype=np.float32)
    assert np.array_equal(got, want) and got[7, 2] == 1.0  # the fault column


def test_library_uses_no_allocation_io_or_exit(pendulum):
    """The static library references no malloc/free/printf/exit (nm on the archive built for an artifact)."""
    lib = build(pendulum.artifact, target="host").files["static"]

    def symbols(*flags):
        out = subprocess.run(["nm", *flags, str(lib)], capture_output=True, text=True, check=True).stdout
        return {line.split()[-1] for line in out.splitlines() if line.strip() and not line.endswith(":")}

    undefined = symbols("-u") - symbols("--defined-only")
    forbidden = {"malloc", "calloc", "realloc", "free", "printf", "fprintf", "puts", "exit", "abort"}
    assert not undefined & forbidden, f"library references {sorted(undefined & forbidden)}"
    assert undefined <= {"fmaf", "memcpy", "memset", "__stack_chk_fail", "_GLOBAL_OFFSET_TABLE_"}, sorted(undefined)


def test_a_finished_build_is_not_run_again_until_a_product_is_missing(pendulum, tmp_path, monkeypatch):
    """build() of a target it finished from the same sources starts no CMake; once a product of the tree is gone,
    it builds again and the product is back."""
    from gainlink.firmware import build as build_mod

    a = pendulum.artifact
    first = build(a, build_root=tmp_path, only="gainlink_host")
    library = first.files["shared"]
    assert library.is_file()
    calls: list[list[str]] = []
    real_run = build_mod._run
    monkeypatch.setattr(build_mod, "_run", lambda cmd, **kw: (calls.append(cmd), real_run(cmd, **kw))[1])
    assert build(a, build_root=tmp_path, only="gainlink_host").files["shared"] == library
    assert calls == []
    library.unlink()
    build(a, build_root=tmp_path, only="gainlink_host")
    # one build of that target (Ninja's or CMake's command), no configure
    assert len(calls) == 1 and "-S" not in calls[0] and calls[0][-1] == "gainlink_host" and library.is_file()
