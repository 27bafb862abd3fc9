"""The fixed-point headline (``checks.fixed_point.error.certified``) covers the loop in operation: twin loops around
the design model, the integer law (gainlink.laws.fixed.model, bit for bit the C; its command as the float the C
returns) and the design's float64 law written here from the contract (support.fixed.DesignLaw), sharing a random
initial plant state within the declared ranges, input disturbances, measurement noise and references within their
ranges. While neither saturates and no sample is clipped, the commands never differ by more than the headline.

The certificate once drove its coefficient term by the references alone (and left out the float the C returns): a
regulator started from a non-zero state left the design's law by 1.7 times that figure (seed 8, q31, below) and
1.6 times (seed 3, q15). ``make test`` runs a few
designs (stable and unstable plants, regulators and trackers, both observer forms, q31 and q15); the sweep is
``matrix``-marked."""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.errors import DesignError
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.qformat import real
from gainlink.shipping.artifact import from_dict
from gainlink.synthesis.random_plants import random_spec
from support.designs import designed
from support.fixed import DesignLaw, c_float

Y_RANGE, R_RANGE, U_LIMIT = 2.0, 1.0, 20.0  # limits wide enough that the premise (unsaturated) holds for a while

# (seed, random_spec options, numeric, plant): "unstable" or "stable" as generated, or "stabilised" (its modes
# moved left of the imaginary axis)
CASES = [
    (8, dict(n=2, m=1, p=1), "q31", "unstable"),  # a regulator: 1.7x the old figure
    (3, dict(n=3, m=1, p=1), "q15", "unstable"),  # likewise in q15: 1.6x
    (0, dict(n=3, m=1, p=1, q=1, anti_windup="backcalc"), "q31", "unstable"),
    (4, dict(n=3, m=1, p=1, q=1, anti_windup="clamp"), "q15", "stabilised"),
    (7, dict(n=4, m=2, p=2, q=1, form="current", anti_windup="backcalc"), "q15", "stable"),
]
SWEEP = [
    (seed, kw, numeric, plant)
    for seed in range(12)
    for kw in (
        dict(n=3, m=1, p=1),
        dict(n=3, m=1, p=1, q=1, anti_windup="clamp"),
        dict(n=4, m=2, p=2, form="current"),
        dict(n=3, m=2, p=2, q=1, form="current", anti_windup="backcalc"),
    )
    for numeric in ("q31", "q15")
    for plant in ("as generated", "stabilised")
]


def _ids(cases) -> list[str]:
    return [
        f"seed{s}-{kw.get('form', 'predictor')}-q{kw.get('q', 0)}-{num}-{plant.replace(' ', '-')}"
        for s, kw, num, plant in cases
    ]


def _design(seed: int, kw: dict, numeric: str, plant: str):
    """A random design certified in ``numeric`` (None when the certificate refuses it: a q15 law the quantised
    coefficients destabilise, say); a ``stabilised`` plant has its modes moved left."""
    spec = random_spec(seed, u_limit=U_LIMIT, **kw)
    if plant == "stabilised":
        A = np.array(spec["plant"]["A"])
        spec["plant"]["A"] = (A - (np.max(np.linalg.eigvals(A).real) + 0.5) * np.eye(A.shape[0])).tolist()
    spec["limits"] |= {"y_min": [-Y_RANGE] * kw["p"], "y_max": [Y_RANGE] * kw["p"]}
    if kw.get("q"):
        spec["limits"] |= {"r_min": [-R_RANGE] * kw["q"], "r_max": [R_RANGE] * kw["q"]}
    spec["implementation"] = {"numeric": numeric, "float32_check": False, "fixed_point_max_error": 0.5}
    try:
        return from_dict(designed(spec))
    except DesignError:
        return None


def _twin(a, rng, *, steps: int, disturbance: float, noise: float) -> tuple[np.ndarray, int]:
    """One twin run (module docstring) from a random initial state whose samples fill 30-70 % of their room (the
    estimate starts at the law's own initial value, so the samples move on before it converges); the largest
    command difference per input and the number of steps before either law saturated or a sample was clipped."""
    room = np.minimum(Y_RANGE - a.y_op, a.y_op + Y_RANGE)
    x0 = rng.standard_normal(a.n)
    x0 *= rng.uniform(0.3, 0.7) * np.min(room / np.maximum(np.abs(a.Cd @ x0), 1e-12))
    levels = rng.uniform(-0.9 * R_RANGE, 0.9 * R_RANGE, (steps // 50 + 1, a.q))
    design, integer = DesignLaw(a), FixedPointLoop(a)
    fu = integer.f["u"]
    x, du = [x0.copy(), x0.copy()], [np.zeros(a.m), np.zeros(a.m)]
    worst = np.zeros(a.m)
    for k in range(steps):
        n = noise * room * rng.uniform(-1, 1, a.p)
        y = [a.y_op + a.Cd @ x[i] + a.Dd @ du[i] + n for i in (0, 1)]
        r = levels[k // 50]
        u_design, saturated = design.step(y[0], r)
        s = integer.step_samples(y[1], r)
        if saturated or s.saturated.any() or s.clipped_y.any() or s.clipped_r.any():
            return worst, k
        u_integer = c_float(real(s.U, fu))
        worst = np.maximum(worst, np.abs(u_integer - u_design))
        w = disturbance * 0.5 * (a.u_max - a.u_min) * rng.uniform(-1, 1, a.m)
        for i, u in enumerate((u_design, u_integer)):
            du[i] = u - a.u_op
            x[i] = a.Ad @ x[i] + a.Bd @ (du[i] + w)
    return worst, steps


def _check(case, *, runs: int, steps: int) -> tuple[np.ndarray, int] | None:
    """Twin runs of one case against its headline: the largest ratio of difference to bound per input and the
    steps covered (None: the case was refused at design)."""
    a = _design(*case)
    if a is None:
        return None
    seed, _, _, plant = case
    if plant != "as generated":
        assert (np.max(np.abs(np.linalg.eigvals(a.Ad))) < 1.0) == (plant != "unstable"), plant
    bound = np.array(a.checks["fixed_point"]["error"]["certified"])
    rng = np.random.default_rng(seed)
    worst, covered = np.zeros(a.m), 0
    for run in range(runs):
        dev, k = _twin(a, rng, steps=steps, disturbance=0.01 * (run % 3), noise=0.002 * (run % 2))
        worst, covered = np.maximum(worst, dev), covered + k
    assert np.all(worst <= bound), f"the twin loops differ by {worst}, above the headline {bound}"
    return worst / bound, covered


@pytest.mark.parametrize("case", CASES, ids=_ids(CASES))
def test_twin_loops_stay_within_the_headline(case):
    ratio, covered = _check(case, runs=8, steps=300)
    assert covered >= 300  # the unsaturated, unclipped window the bound is about was exercised
    assert ratio.max() > 0.01  # a worst case over every history, not a vacuous one


@pytest.mark.matrix
@pytest.mark.parametrize("case", SWEEP, ids=_ids(SWEEP))
def test_twin_loops_stay_within_the_headline_on_a_sweep(case):
    result = _check(case, runs=6, steps=300)
    if result is None:
        pytest.skip(f"refused at design in {case[2]}")
