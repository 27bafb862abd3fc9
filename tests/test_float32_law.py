"""The numpy statement of the C's float32 arithmetic (gainlink.proof.float32_law) against the real host build.

Oracles: the C library through ctypes (bit for bit) and libm's own fmaf (for the rounding primitive).
"""

from __future__ import annotations

import ctypes
import ctypes.util

import numpy as np
import pytest
from gainlink.engines.native import NativeLoop
from gainlink.firmware.golden import example_cases
from gainlink.proof.float32_law import Float32Loop, fma32_exact
from support.paths import EXAMPLES

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
    cases = example_cases(EXAMPLES) if source == "examples" else _structures(request.getfixturevalue(source))
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
