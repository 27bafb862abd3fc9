"""The fixed-point C (firmware/src/gl_fixed.c) against the bit-exact integer model gainlink.laws.fixed.model: the
host build step for step (command words, unsaturated commands, estimate, integrators, every flag) on the three
examples (q31; q15 where the certificate allows it: wood_berry) and on seeded random designs (both observer forms,
clamp and back-calculation, q31 and q15); samples outside their ranges clipped and flagged, a NaN refused with the
safe command, the second-line saturation flagged as the model flags it; the Cortex-M0 and M3 images under QEMU
equal to the host bit for bit. The export of a float32 artifact is unchanged."""

from __future__ import annotations

import copy
import subprocess

import numpy as np
import pytest
from gainlink.fileio import read_toml
from gainlink.firmware.build import build
from gainlink.laws.fixed.firmware import CLIPPED, FAULT, OVERFLOW, OVERFLOW_BITS, run_host, run_qemu
from gainlink.laws.fixed.model import gains_from_artifact
from gainlink.laws.fixed.qformat import WORDS, real
from gainlink.shipping.artifact import from_dict, seal
from gainlink.shipping.codegen import render_c
from gainlink.shipping.export_c import render_export
from support.designs import designed
from support.fixed import DesignLaw, example, model_run, random_design
from support.paths import EXAMPLES as SPECS

EXAMPLES = [("pendulum", "q31"), ("quadrotor_lateral", "q31"), ("wood_berry", "q31"), ("wood_berry", "q15")]
RANDOM = [  # (seed, options, numeric): both forms, clamp and back-calculation, q31 and q15
    (0, dict(n=3, m=1, p=1, q=1, anti_windup="backcalc"), "q31"),
    (4, dict(n=4, m=2, p=2, q=1, form="current", anti_windup="clamp"), "q15"),
    (9, dict(n=4, m=2, p=2, q=1, form="current", anti_windup="clamp"), "q31"),
    (7, dict(n=3, m=1, p=1, q=1, anti_windup="backcalc"), "q15"),
    (10, dict(n=3, m=2, p=2, form="current", anti_windup="none"), "q15"),  # no integrator
]
STEPS = 400


def _samples(a, steps: int, seed: int, beyond: float = 1.2) -> tuple[np.ndarray, np.ndarray]:
    """float32 samples and references spread over their declared ranges and a little past them (clipped)."""
    rng = np.random.default_rng(seed)
    ranges = a.checks["fixed_point"]["ranges"]

    def draw(lo, hi, size):
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        mid, half = (lo + hi) / 2, (hi - lo) / 2
        return (mid + beyond * half * rng.uniform(-1, 1, (steps, size))).astype(np.float32)

    Y = draw(ranges["y_min"], ranges["y_max"], a.p)
    R = draw(ranges["r_min"], ranges["r_max"], a.q) if a.q else np.zeros((steps, 0), dtype=np.float32)
    return Y, R


def assert_same(a, run, ref) -> None:
    """The C run equals the model step for step, bit for bit."""
    for name in ("U", "V", "XH", "Z", "sat", "clip"):
        got, want = getattr(run, name), getattr(ref, name)
        bad = np.flatnonzero(
            np.any(np.asarray(got).reshape(len(got), -1) != np.asarray(want).reshape(len(want), -1), axis=1)
        )
        assert bad.size == 0, f"{name} differs first at step {bad[0] if bad.size else None}"
    assert np.array_equal(run.flags & FAULT != 0, ref.fault)
    names = [{k for k, bit in OVERFLOW_BITS.items() if mask & bit} for mask in run.overflow]
    assert names == [o - {"acc_v", "acc_z", "acc_x"} for o in ref.overflow]
    assert np.array_equal((run.flags & CLIPPED) != 0, ref.clip != 0)
    fu = np.array(a.checks["fixed_point"]["formats"]["u"])
    assert np.array_equal(run.u, real(run.U, fu).astype(np.float32))  # the float command is the word's value


def test_float32_export_is_unchanged():
    """A float32 artifact exports exactly the four files it did (their bytes: tests/test_codegen.py)."""
    a = from_dict(copy.deepcopy(_float_pendulum()))
    assert sorted(render_c(a)) == ["gl_gains.c", "gl_gains.h", "gl_gains_layout.h", "gl_step.h"]


def _float_pendulum() -> dict:
    data = copy.deepcopy(example("pendulum", "q31").data)
    del data["checks"]["fixed_point"]
    return seal(data)


def test_fixed_export_holds_the_stored_integers():
    a = example("pendulum", "q31")
    files = render_export(a)
    assert {"gl_fixed_gains.h", "gl_fixed_gains.c", "gl_fixed_step.h"} <= set(files)
    assert "#define GL_NUMERIC_Q31 1" in files["gl_fixed_gains.h"]
    table = a.checks["fixed_point"]["integers"]
    first = next(c for c in table["KX"][0] if c != 0)
    assert f".coef = {{{first}," in files["gl_fixed_gains.c"]
    assert render_export(a) == files  # deterministic


@pytest.mark.parametrize("name,numeric", EXAMPLES, ids=[f"{n}-{q}" for n, q in EXAMPLES])
def test_host_equals_the_model_on_the_examples(name, numeric):
    a = example(name, numeric)
    Y, R = _samples(a, STEPS, seed=1)
    run = run_host(a, Y, R)
    ref = model_run(a, Y, R)
    assert_same(a, run, ref)
    assert (run.clip != 0).any() and (run.sat != 0).any()  # the ranges' edges and the limits are exercised
    assert not (run.flags & OVERFLOW).any()  # in range: the second line never fires


@pytest.mark.parametrize(
    "case", RANDOM, ids=[f"seed{s}-{kw.get('form', 'predictor')}-{kw['anti_windup']}-{q}" for s, kw, q in RANDOM]
)
def test_host_equals_the_model_on_random_designs(case):
    seed, kw, numeric = case
    a = random_design(seed, numeric, **kw)
    Y, R = _samples(a, STEPS, seed=seed)
    assert_same(a, run_host(a, Y, R), model_run(a, Y, R))


def test_generic_loop_equals_the_generated_rows():
    a = example("pendulum", "q31")
    Y, R = _samples(a, 200, seed=3)
    unrolled, generic = run_host(a, Y, R), run_host(a, Y, R, options={"GL_FIXED_UNROLLED": "OFF"})
    for name in ("U", "V", "XH", "Z", "flags", "sat", "clip", "overflow"):
        assert np.array_equal(getattr(unrolled, name), getattr(generic, name)), name


def test_sample_out_of_range_is_clipped_and_flagged():
    a = example("pendulum", "q31")
    ranges = a.checks["fixed_point"]["ranges"]
    Y = np.array(
        [[ranges["y_max"][0] + 1.0, 0.0], [ranges["y_max"][0], 0.0], [0.0, ranges["y_min"][1] - 0.25]], dtype=np.float32
    )
    R = np.array([[0.0], [ranges["r_max"][0] * 3], [0.0]], dtype=np.float32)
    run = run_host(a, Y, R)
    assert list(run.clip) == [0b001, 0b100, 0b010] and list(run.flags & CLIPPED) == [CLIPPED] * 3
    assert_same(a, run, model_run(a, Y, R))


def test_nan_is_refused_with_the_safe_command():
    a = example("pendulum", "q31")
    Y, R = _samples(a, 6, seed=4, beyond=0.5)
    Y[3, 1] = np.nan
    R[4, 0] = np.inf
    run = run_host(a, Y, R)
    safe = a.checks["fixed_point"]["integers"]["U_SAFE"]
    for k in (3, 4):
        assert run.flags[k] == FAULT and list(run.U[k]) == safe
        assert np.array_equal(run.XH[k], run.XH[2]) and np.array_equal(run.Z[k], run.Z[2])  # state untouched
    assert_same(a, run, model_run(a, Y, R))


def test_second_line_saturation_is_flagged_as_the_model_flags_it():
    """Integers that no longer keep V within 32 bits (an edited mantissa and initial estimate, used as stored):
    the C saturates and flags exactly where the model does."""
    data = copy.deepcopy(example("pendulum", "q31").data)
    integers = data["checks"]["fixed_point"]["integers"]
    integers["KX"][0][1] = integers["XH0"][1] = 2**31 - 1  # KX XH0 = 2^62: V leaves 32 bits in the first step
    a = from_dict(seal(data))
    Y, R = _samples(a, 100, seed=5, beyond=1.0)
    run = run_host(a, Y, R)
    assert (run.overflow & OVERFLOW_BITS["V"]).any() and ((run.flags & OVERFLOW) != 0).any()
    assert_same(a, run, model_run(a, Y, R))


def test_a_u_op_at_a_limit_leaves_the_command_deviation_within_its_word():
    """The pendulum in q31 with limits +-16 and u_op = -16 + 2^-25: u_op rounded in the coarser of the command's two
    formats lands on -16, so HI_U - UOP_U was 2^31, one past the command word, and the C flagged GL_FX_OVERFLOW
    (dU) at step 1 on samples and a reference within their ranges. The command's format now holds every deviation
    as the integers hold them."""
    data, _ = read_toml(SPECS / "pendulum.toml", what="spec", error=ValueError)
    data["limits"] |= {"u_min": [-16.0], "u_max": [16.0]}
    data["operating_point"] = {"u_op": [-16.0 + 2.0**-25], "y_op": [0.0, 0.0]}
    data["implementation"] = {"numeric": "q31"}
    a = from_dict(designed(data))
    Y, R = np.tile([0.0, 0.5], (3, 1)), np.full((3, 1), -1.0)
    run = run_host(a, Y, R)
    g = gains_from_artifact(a)
    assert list(run.U[1:, 0]) == [g.HI_U[0]] * 2  # the command at its upper limit: the deviation's extreme
    assert not (run.flags & OVERFLOW).any(), [{k for k, b in OVERFLOW_BITS.items() if m & b} for m in run.overflow]
    assert g.HI_U[0] - g.UOP_U[0] < 2 ** (WORDS["q31"]["command"] - 1)


@pytest.mark.parametrize("name,numeric", [("pendulum", "q31"), ("wood_berry", "q15")])
def test_the_float_the_c_returns_is_within_the_per_step_bound(name, numeric):
    """Resynchronised: before each step the design's float64 law (written from the contract, with the design's own
    coefficients) takes the host C's state; the float command the C returns (``(float)U`` times ``2^-f_u``) is
    within ``error.per_step`` of it. In q31 that float is up to half a float32 unit of the command word away from
    the word's value (4x the rounding alone on the pendulum), and the coefficients' quantisation moves the command
    too: both are in the bound (and, on saturated steps, how far the quantised limits moved)."""
    a = example(name, numeric)
    fp = a.checks["fixed_point"]
    Y, R = _samples(a, STEPS, seed=9, beyond=0.9)
    run = run_host(a, Y, R)
    law = DesignLaw(a)
    f_xh, f_z = np.array(fp["formats"]["xh"]), np.array(fp["formats"]["z"])
    worst = np.zeros(a.m)
    for k in range(STEPS):
        if k:
            law.xh, law.z = real(run.XH[k - 1], f_xh), real(run.Z[k - 1], f_z)
        u, _ = law.step(Y[k].astype(np.float64), R[k].astype(np.float64))
        worst = np.maximum(worst, np.abs(run.u[k].astype(np.float64) - u))
    bound = np.array(fp["error"]["per_step"])
    assert np.all(worst <= bound), f"{worst} > {bound}"
    assert np.any(worst > 0.1 * bound)  # the bound is of the size of what happens


@pytest.mark.parametrize("target", ["cortex-m0", "cortex-m3"])
def test_qemu_equals_the_host_bit_for_bit(target):
    a = example("wood_berry", "q15") if target == "cortex-m0" else example("pendulum", "q31")
    Y, R = _samples(a, 300, seed=6)
    host, image = run_host(a, Y, R), run_qemu(a, Y, R, target=target)
    for name in ("U", "V", "XH", "Z", "flags", "sat", "clip", "overflow"):
        assert np.array_equal(getattr(host, name), getattr(image, name)), name
    assert np.array_equal(host.u.view(np.uint32), image.u.view(np.uint32))


def test_host_executable_under_asan_ubsan_matches_the_library():
    """Built with -fsanitize=address,undefined (shifts, signed overflow, bounds), the host executable (one main for
    every law: here the integer law) runs clean on samples past their ranges, a NaN and a reset, and agrees with the
    ctypes library bit for bit. Its step lines hold the record: status, flags, sat, u (m floats), then U, V (m), XH
    (n), Z (q), clip, overflow."""
    seed, kw, numeric = RANDOM[1]  # current form, clamp, q15
    for a in (example("pendulum", "q31"), random_design(seed, numeric, **kw)):
        sanitized = build(a, target="host", options={"GL_SANITIZE": "ON"}, only="gainlink_loop_host")
        exe = sanitized.files["exe"]
        Y, R = _samples(a, 80, seed=8)
        Y[40, 0] = np.nan
        lines = [" ".join(repr(float(v)) for v in np.concatenate([Y[k], R[k]])) for k in range(len(Y))]
        script = lines + ["reset", "bogus"] + lines[:10]
        proc = subprocess.run([str(exe)], input="\n".join(script) + "\n", capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2  # the line "bogus"
        assert "runtime error" not in proc.stderr and "Sanitizer" not in proc.stderr, proc.stderr
        assert f"law={a.checks['fixed_point']['numeric']}" in proc.stdout.splitlines()[0]
        steps = [line.split()[1:] for line in proc.stdout.splitlines() if line.startswith("step ")]
        run = run_host(a, Y, R)
        m = a.m
        for k in range(len(Y)):
            words = steps[k]
            status, flags, sat = (int(v) for v in words[:3])
            ints = [int(v) for v in words[3 + m :]]
            assert [flags, sat, ints[-2], ints[-1]] == [run.flags[k], run.sat[k], run.clip[k], run.overflow[k]]
            assert status == (-2 if run.flags[k] & FAULT else int(run.sat[k] != 0)), k
            assert ints[:-2] == [*run.U[k], *run.V[k], *run.XH[k], *run.Z[k]], k
        assert steps[len(Y) :] == steps[:10]  # reset: the same steps again
        assert "error expected" in proc.stdout
