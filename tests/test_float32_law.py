"""The numpy statement of the C's float32 arithmetic (gainlink.laws.lq.model) against the real host build.

Oracles: the C library through ctypes (bit for bit) and libm's own fmaf (for the rounding primitive).
"""

from __future__ import annotations

import ctypes
import ctypes.util

import numpy as np
import pytest
from gainlink.engines.native import NativeLoop
from gainlink.laws.lq.model import Float32Loop, fma32_exact
from support.designs import golden_examples

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def _bits(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float32).view(np.uint32)


def test_fma32_is_correctly_rounded_like_libm_fmaf():
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    libm.fmaf.argtypes = [ctypes.c_float] * 3
    libm.fmaf.restype = ctypes.c_float
    rng = np.random.default_rng(3)
    a = rng.standard_normal(20000).astype(np.float32)
    b = (rng.standard_normal(20000) * 10.0 ** rng.integers(-8, 8, 20000)).astype(np.float32)
    c = (rng.standard_normal(20000) * 10.0 ** rng.integers(-8, 8, 20000)).astype(np.float32)
    # Cases where a*b + c rounded to double lands on a float32 midpoint but the exact sum does not:
    # a*b = 2^-24 (1 + 2^-12)(1 - 2^-12 + 2^-24) = 2^-24 + 2^-60, so 1 + a*b is the midpoint 1 + 2^-24 plus
    # 2^-60, which double cannot hold; the correctly rounded result is 1 + 2^-23, not the tie's 1.
    a[:64], b[:64], c[:64] = np.float32(2.0**-24 * (1 + 2.0**-12)), np.float32(1 - 2.0**-12 + 2.0**-24), 1.0
    a[32:64], c[32:64] = -a[32:64], -1.0
    tie_hits = 0
    for x, y, z in zip(a.tolist(), b.tolist(), c.tolist()):
        want = libm.fmaf(x, y, z)
        got = fma32_exact(x, y, z)
        assert np.float32(got).view(np.uint32) == np.float32(want).view(np.uint32), (x, y, z)
        s = x * y + z
        tie_hits += float(np.float32(s)) != got
    assert tie_hits >= 64, "the double-rounding cases were exercised (plain rounding from double gets them wrong)"


def test_a_step_whose_fmaf_sum_sits_on_a_midpoint_is_redone_with_one_rounding(pend):
    """The unrolled fast step (gainlink.laws.lq.step) rounds each fmaf twice (to double, then to float32); when
    a double sum sits on a float32 midpoint that the exact sum does not, the step is redone exactly. Here the first
    command's sum is 1 + a*b with a*b = 2^-24 + 2^-60 (the case of the test above): libm's fmaf gives 1 + 2^-23,
    the double rounding 1."""
    from gainlink.laws.lq.step import compile_step
    from gainlink.shipping.artifact import load

    a = load(pend)
    assert a.observer_form == "predictor"
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    libm.fmaf.argtypes = [ctypes.c_float] * 3
    libm.fmaf.restype = ctypes.c_float
    gain, state = float(np.float32(2.0**-24 * (1 + 2.0**-12))), float(np.float32(1 - 2.0**-12 + 2.0**-24))
    loop = Float32Loop(a)
    w = [0.0] * len(loop.w)  # y_op = 0, u_op = 0, every other coefficient 0 except the first command's
    first = a.p  # u_op of the first command row, then its state gains Kx[0, :], integrator gains, lo, hi
    w[first + 1], w[first + 2] = 1.0, gain
    w[first + 1 + a.n + a.q], w[first + 2 + a.n + a.q] = -10.0, 10.0
    loop.w = w
    loop._fast = compile_step(w, n=a.n, m=a.m, p=a.p, q=a.q, current=False, anti_windup=a.anti_windup)
    xh = [1.0, state] + [0.0] * (a.n - 2)
    loop.xh = np.array(xh)
    *_, inexact = loop._fast(xh, [0.0] * a.q, [0.0] * a.p, [0.0] * a.q)
    assert inexact, "the fast step flags its double rounding"
    u = loop.step(np.zeros(a.p), np.zeros(a.q)).u
    assert float(np.float32(1.0 + gain * state)) == 1.0, "double rounding alone gets this wrong"
    assert _bits(u[0]) == _bits(libm.fmaf(gain, state, 1.0)) == _bits(1.0 + 2.0**-23)


def _structures(cases) -> list:
    """One case per compiled structure (form, anti-windup mode, integrators, operating point)."""
    picked = {}
    for case in cases:
        a = case.artifact
        picked.setdefault((a.observer_form, a.anti_windup, a.q > 0, a.has_operating_point), case)
    return list(picked.values())


def test_the_compared_cases_cover_every_structure(random_designs, closed_loop_designs):
    cases = _structures(random_designs) + _structures(closed_loop_designs)
    assert any(c.artifact.has_operating_point for c in cases) and any(c.artifact.M is not None for c in cases)
    assert {(c.artifact.observer_form, c.artifact.anti_windup) for c in cases} >= {
        (f, aw) for f in ("predictor", "current") for aw in ("none", "clamp", "backcalc")
    }


@pytest.mark.parametrize("source", ["examples", "random_designs", "closed_loop_designs"])  # three workers
@pytest.mark.slow
def test_float32_loop_equals_the_host_build_bit_for_bit(source, request):
    """The numpy float32 model equals the host build bit for bit (a refused sample included), on the examples
    and on one random design per compiled structure."""
    cases = golden_examples() if source == "examples" else _structures(request.getfixturevalue(source))
    for case in cases:
        Y = case.Y.copy()
        Y[11, 0] = np.nan  # a refused sample: the safe command, state kept
        c = NativeLoop(case.artifact).run_raw(Y, case.R)
        py = Float32Loop(case.artifact).run(Y, case.R)
        for key in ("u", "xh", "z"):
            assert np.array_equal(_bits(c[key]), _bits(getattr(py, key))), f"{case.label}: {key}"
        sat = ((c["sat"][:, None] >> np.arange(case.artifact.m)) & 1).astype(bool)
        assert np.array_equal(sat, py.saturated) and np.array_equal(c["fault"].astype(bool), py.fault), case.label
        assert py.saturated.any(), f"{case.label}: the samples should saturate"
