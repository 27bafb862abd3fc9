"""The bit-exact integer model of the fixed-point law against independent oracles: exact rational arithmetic for
one step, the float64 law (gainlink.proof.reference) for the structure, and the certificate's bounds on seeded
random designs (stable and unstable plants, both observer forms, every anti-windup mode a fixed-point law allows,
stable and unstable compensators, q31 and q15)."""

from __future__ import annotations

import hashlib
import math
from fractions import Fraction

import numpy as np
import pytest
from gainlink.laws import design as design_spec
from gainlink.laws.fixed.certificate import certify
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.qformat import quantise, rshift_round
from gainlink.proof.derived_law import DerivedLoop, derive
from gainlink.proof.reference import ReferenceLoop
from gainlink.proof.sampled_plant import SampledPlant
from gainlink.shipping.artifact import from_dict
from gainlink.spec import parse_spec
from gainlink.synthesis.random_plants import random_spec
from support.shared import once

# (seed, random_spec options, numeric): chosen to cover stable plants (4, 7, 10) and unstable ones (0, 2, 9), both
# forms, clamp, back-calculation and no integrator, and unstable compensators (2: |z| = 1.14; 4 current: 1.11)
CASES = [
    (0, dict(n=3, m=1, p=1, q=1, anti_windup="backcalc"), "q31"),
    (0, dict(n=4, m=2, p=2, q=1, form="current", anti_windup="clamp"), "q15"),
    (2, dict(n=3, m=1, p=1, q=1, anti_windup="backcalc"), "q31"),
    (4, dict(n=4, m=2, p=2, q=1, form="current", anti_windup="clamp"), "q15"),
    (4, dict(n=3, m=2, p=2), "q31"),
    (7, dict(n=3, m=1, p=1, q=1, anti_windup="backcalc"), "q15"),
    (9, dict(n=4, m=2, p=2, q=1, form="current", anti_windup="clamp"), "q31"),
    (10, dict(n=3, m=2, p=2, form="current"), "q15"),
]
IDS = [f"seed{s}-{kw.get('form', 'predictor')}-{kw.get('anti_windup', 'none')}-{num}" for s, kw, num in CASES]
Y_RANGE, R_RANGE = 2.0, 1.0


def _ranges(a) -> dict:
    q = a.q
    return {
        "y_min": [-Y_RANGE] * a.p,
        "y_max": [Y_RANGE] * a.p,
        "r_min": [-R_RANGE] * q if q else None,
        "r_max": [R_RANGE] * q if q else None,
    }


_CACHE: dict = {}


def _no_float32(spec: dict) -> dict:
    """The spec without the design-time float32 check (not what these tests are about; it costs a second)."""
    return spec | {"implementation": {"float32_check": False}}


def _design(case):
    """The case's artifact and certificate, made once per test run (support.shared.once: the cases' tests are
    spread over the workers, and each worker designed and certified every case again, 5 CPU-s for the eight)."""
    key = repr(case)
    if key not in _CACHE:
        _CACHE[key] = once(f"fixed-law-{hashlib.sha256(key.encode()).hexdigest()[:16]}", lambda: _certified(case))
    return _CACHE[key]


def _certified(case):
    seed, kw, numeric = case
    a = from_dict(design_spec(parse_spec(_no_float32(random_spec(seed, **kw)))).artifact)
    return a, certify(a, _ranges(a), numeric=numeric, max_error=1.0)


def _in_range(rng, a, steps: int, corners: bool) -> tuple[np.ndarray, np.ndarray]:
    """Samples and references within their ranges: uniform, or at the corners (the hostile extremes)."""
    if corners:
        return Y_RANGE * rng.choice([-1.0, 1.0], (steps, a.p)), R_RANGE * rng.choice([-1.0, 1.0], (steps, a.q))
    return rng.uniform(-Y_RANGE, Y_RANGE, (steps, a.p)), rng.uniform(-R_RANGE, R_RANGE, (steps, a.q))


# ---------------------------------------------------------------------------------------------------------------
# the primitives


def test_quantise_rounds_to_nearest_ties_up_exactly():
    rng = np.random.default_rng(0)
    x = np.concatenate(
        [rng.standard_normal(500) * 10, [0.5, -0.5, 1.5, -2.5, 0.49999999999999994, -0.49999999999999994]]
    )
    for frac in (0, 3, 20, -2):
        got = quantise(x, frac)
        want = [math.floor(Fraction(float(v)) * Fraction(2) ** frac + Fraction(1, 2)) for v in x]
        assert got.tolist() == want


def test_rshift_round_is_round_half_up():
    values = np.array(
        [-9, -8, -7, -6, -5, -4, -3, -2, -1, 0, 1, 2, 3, 5, 6, 7, 2**40 + 3, -(2**40) - 3], dtype=np.int64
    )
    for s in (1, 2, 3, 5):
        want = [math.floor(Fraction(int(v), 2**s) + Fraction(1, 2)) for v in values]
        assert rshift_round(values, s).tolist() == want
    assert rshift_round(values, -3).tolist() == (values * 8).tolist()


# ---------------------------------------------------------------------------------------------------------------
# the law's structure


@pytest.mark.parametrize("form", ["predictor", "current"])
@pytest.mark.parametrize("aw", ["none", "clamp", "backcalc"])
def test_derived_law_is_the_reference_law(form, aw):
    """The C's form of the law (one sum of products per output) is the float64 law of docs/design.md."""
    spec = _no_float32(random_spec(3, n=4, m=2, p=2, q=1, form=form, anti_windup=aw))
    a = from_dict(design_spec(parse_spec(spec)).artifact)
    rng = np.random.default_rng(1)
    Y, R = rng.uniform(-1.0, 1.0, (300, 2)), rng.uniform(-1.0, 1.0, (300, 1))
    ours, ref = DerivedLoop(derive(a)).run(Y, R), ReferenceLoop(a).run(Y, R)
    assert np.abs(ours.u - ref.u).max() < 1e-12 * max(1.0, np.abs(ref.u).max())
    assert np.abs(ours.xh - ref.xh).max() < 1e-10 * max(1.0, np.abs(ref.xh).max())
    assert np.array_equal(ours.saturated, ref.saturated)


def _exact_round(x: Fraction, frac: int) -> int:
    return math.floor(x * Fraction(2) ** frac + Fraction(1, 2))


def _fr(values) -> list[Fraction]:
    return [Fraction(float(v)) for v in np.ravel(values)]


def _dot(M, x) -> list[Fraction]:
    M = np.atleast_2d(M)
    return [sum((Fraction(float(c)) * v for c, v in zip(row, x)), Fraction(0)) for row in M]


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_one_integer_step_is_the_exactly_rounded_ideal_step(case):
    """Oracle: the ideal law's real coefficients in exact rationals, each output rounded once (half up) into its
    format. No mantissas, shifts or accumulators: what the integers must mean."""
    a, cert = _design(case)
    g = cert.quantised.gains
    law, fm = g.ideal, g.formats
    f = {k: fm.frac(k) for k in ("y", "r", "u", "v", "xh", "z")}
    loop = FixedPointLoop(g)
    rng = np.random.default_rng(2)
    for k in range(200):  # reachable states: the law's own, driven by inputs in range
        XH, Z = list(loop.XH), list(loop.Z)
        y, r = (x[0] for x in _in_range(rng, a, 1, corners=k % 2 == 0))
        Y, R, _, _ = loop.quantise_samples(y, r)
        res = loop.step_int(Y, R)
        assert res.overflow == ()
        xh = [Fraction(x) * Fraction(2) ** -int(fx) for x, fx in zip(XH, f["xh"])]
        z = [Fraction(x) * Fraction(2) ** -int(fz) for x, fz in zip(Z, f["z"])]
        yv = [Fraction(int(x)) * Fraction(2) ** -int(fy) for x, fy in zip(Y, f["y"])]
        rv = [Fraction(int(x)) * Fraction(2) ** -int(fr) for x, fr in zip(R, f["r"])]
        dy = [v - o for v, o in zip(yv, _fr(law.y_op))]
        c = [p + q_ + s for p, q_, s in zip(_dot(law.Kx, xh), _dot(law.Ky, dy), _dot(law.Kz, z))]
        V = [_exact_round(uop + ci, int(fv)) for uop, ci, fv in zip(_fr(law.u_op), c, f["v"])]
        assert res.V.tolist() == V
        uv = [min(max(Fraction(v) * Fraction(2) ** -int(fv), lo), hi) for v, fv, lo, hi in
              zip(V, f["v"], _fr(law.lo), _fr(law.hi))]  # fmt: skip
        U = [_exact_round(u, int(fu)) for u, fu in zip(uv, f["u"])]
        assert res.U.tolist() == U
        du = [Fraction(u) * Fraction(2) ** -int(fu) - o for u, fu, o in zip(U, f["u"], _fr(law.u_op))]
        acc = [p + q_ + s for p, q_, s in zip(_dot(law.F, xh), _dot(law.G, du), _dot(law.Ly, dy))]
        assert loop.XH == [_exact_round(x, int(fx)) for x, fx in zip(acc, f["xh"])]
        if a.q and not (law.anti_windup == "clamp" and res.saturated.any()):
            w = [u - Fraction(v) * Fraction(2) ** -int(fv) for u, v, fv in zip(uv, V, f["v"])]
            inc = [t * rr + s + k for t, rr, s, k in zip(_fr(law.Tr), rv, _dot(law.Ty, yv), _dot(law.Kaw, w))]
            assert loop.Z == [zz + _exact_round(i, int(fz)) for zz, i, fz in zip(Z, inc, f["z"])]
        elif a.q:
            assert loop.Z == Z


def test_fault_leaves_the_state_and_commands_the_safe_value():
    a, cert = _design(CASES[0])
    loop, twin = FixedPointLoop(cert.quantised.gains), FixedPointLoop(cert.quantised.gains)
    rng = np.random.default_rng(3)
    Y, R = _in_range(rng, a, 50, corners=False)
    for k in range(50):
        if k in (10, 11, 30):
            before = (list(loop.XH), list(loop.Z))
            res = loop.step_samples(np.where(k == 11, np.inf, np.nan) * np.ones(a.p), R[k])
            assert res.fault and res.U.tolist() == cert.quantised.gains.U_SAFE.tolist()
            assert (loop.XH, loop.Z) == before
            continue
        assert loop.step_samples(Y[k], R[k]).U.tolist() == twin.step_samples(Y[k], R[k]).U.tolist()
    nan_ref = loop.step_samples(Y[0], np.full(a.q, np.nan))
    assert nan_ref.fault


def test_samples_outside_the_ranges_are_clipped_and_flagged():
    _, cert = _design(CASES[2])
    g = cert.quantised.gains
    outside, edge = FixedPointLoop(g), FixedPointLoop(g)
    res = outside.step_samples([5.0 * Y_RANGE], [-3.0 * R_RANGE])
    assert res.clipped_y.tolist() == [True] and res.clipped_r.tolist() == [True]
    same = edge.step_samples([Y_RANGE], [-R_RANGE])
    assert not same.clipped_y.any() and res.U.tolist() == same.U.tolist() and outside.XH == edge.XH


# ---------------------------------------------------------------------------------------------------------------
# the certificate's bounds, measured


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_no_overflow_and_states_within_bounds_for_hostile_inputs_in_range(case):
    a, cert = _design(case)
    b, g = cert.quantised.bounds, cert.quantised.gains
    loop = FixedPointLoop(g)
    rng = np.random.default_rng(4)
    worst_xh, worst_z = np.zeros(a.n), np.zeros(a.q)
    for corners in (True, False):
        Y, R = _in_range(rng, a, 1500, corners)
        for k in range(Y.shape[0]):
            res = loop.step_samples(Y[k], R[k])
            assert res.overflow == (), res.overflow
            worst_xh, worst_z = np.maximum(worst_xh, np.abs(loop.xh)), np.maximum(worst_z, np.abs(loop.z))
    assert np.all(worst_xh <= b.xh) and np.all(worst_z <= b.z)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_one_step_deviation_within_the_per_step_bound(case):
    """Resynchronised: before each step the float64 law (same quantised coefficients and clip) takes the integer
    law's state; the integer law's command as the float the C returns (``(float)U`` times ``2^-f_u``)."""
    a, cert = _design(case)
    g = cert.quantised.gains
    loop, ideal = FixedPointLoop(g), DerivedLoop(g.ideal)
    rng = np.random.default_rng(5)
    Y, R = _in_range(rng, a, 800, corners=False)
    worst = np.zeros(a.m)
    for k in range(Y.shape[0]):
        ideal.xh, ideal.z = loop.xh, loop.z
        returned = loop.step(Y[k], R[k]).u.astype(np.float32).astype(np.float64)
        worst = np.maximum(worst, np.abs(returned - ideal.step(Y[k], R[k]).u))
    assert np.all(worst <= cert.per_step.u)
    assert np.any(worst > 0.25 * cert.per_step.u)  # the bound is what rounding does, not a safe guess


def _closed_loops(a, laws, steps: int, rng, *, noise: float):
    """Each law closes its own copy of the design plant; same references (small steps) and noise. Returns the
    commands up to the first step where any loop saturated or clipped."""
    plants = [SampledPlant(a.Ad, a.Bd, a.Cd, a.Dd, u_op=a.u_op, y_op=a.y_op) for _ in laws]
    levels = rng.uniform(-0.05 * R_RANGE, 0.05 * R_RANGE, (steps // 100 + 1, a.q))
    U = np.zeros((len(laws), steps, a.m))
    for k in range(steps):
        r, n = levels[k // 100], noise * rng.standard_normal(a.p)
        for i, (law, plant) in enumerate(zip(laws, plants)):
            y = plant.outputs() + n
            res = law.step(y, r)
            if res.saturated.any() or np.any(np.abs(y) > Y_RANGE):
                return U[:, :k]
            U[i, k] = res.u
            plant.advance(res.u)
    return U


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_closed_loop_deviation_within_the_certified_bound(case):
    a, cert = _design(case)
    g = cert.quantised.gains
    U = _closed_loops(a, [FixedPointLoop(g), DerivedLoop(g.ideal)], 2000, np.random.default_rng(6), noise=1e-3)
    assert U.shape[1] > 500
    assert np.all(np.abs(U[0] - U[1]).max(axis=0) <= cert.closed_loop)


@pytest.mark.parametrize(
    "case", [c for c in CASES if c[1].get("q")], ids=[i for c, i in zip(CASES, IDS) if c[1].get("q")]
)
def test_closed_loop_against_the_design_law_within_rounding_plus_coefficients(case):
    """Against the design's own float64 law (gainlink.proof.reference), references only: the rounding bound plus
    the coefficient term."""
    a, cert = _design(case)
    U = _closed_loops(a, [FixedPointLoop(cert.quantised.gains), ReferenceLoop(a)], 2000, np.random.default_rng(7),
                      noise=0.0)  # fmt: skip
    assert U.shape[1] > 500
    assert np.all(np.abs(U[0] - U[1]).max(axis=0) <= cert.closed_loop + cert.coefficients_closed_loop)


def test_open_loop_deviation_within_the_certified_bound():
    """A stable compensator without integrators replayed open loop (unsaturated): the open-loop bound holds."""
    cases = [c for c in CASES if _design(c)[1].open_loop is not None]
    assert cases  # the catalogue has some
    for case in cases:
        a, cert = _design(case)
        g = cert.quantised.gains
        loop, ideal = FixedPointLoop(g), DerivedLoop(g.ideal)
        Y = np.random.default_rng(8).uniform(-0.02 * Y_RANGE, 0.02 * Y_RANGE, (2000, a.p))
        worst = np.zeros(a.m)
        for y in Y:
            ours, theirs = loop.step(y), ideal.step(y)
            if ours.saturated.any() or theirs.saturated.any():
                break
            worst = np.maximum(worst, np.abs(ours.u - theirs.u))
        assert np.all(worst <= cert.open_loop)
