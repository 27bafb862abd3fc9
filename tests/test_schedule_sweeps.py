"""The falsifier's periodic sigma paths (issue 18 item 3; issue 29): triangles over every sub-range of the envelope
on a grid and holds/jumps/ramps between levels, judged by their monodromy matrices, never a certificate.

On the spring of ``schedule_cases`` scheduled 1 -> 400 (no rate certified within the default refinements; its spec
here declares the old simulated rate, 0.5/s, uncertified), sweeping only the whole envelope and each interval gave
50 * 10^(-1.5) = 1.58/s, at which a sweep over half the envelope grows. The oracles are the test's own: the float64
scheduled law (``gainlink.laws.scheduled.reference``) around the interpolated plant, and a transition matrix over
one period built here from the law's step equations (docs/design.md), both stepped sample by sample on paths made
here.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from gainlink.laws.scheduled.rate import (
    RATE_GRID,
    Path,
    dwell_grid,
    monodromy_radius,
    scan_rates,
    triangle,
    worst_path,
)
from gainlink.laws.scheduled.sweeps import sweep_nodes, sweep_radii
from gainlink.laws.scheduled.variation import loops_at
from gainlink.shipping.artifact import from_dict, seal
from schedule_cases import spring
from support.designs import designed

OLD_RATE = 50.0 * 10**-1.5  # the old verdict: the scan's grid rate before the first full-envelope instability
GRID_RATIO = 10 ** (4 / (RATE_GRID - 1))


def _uncertified() -> dict:
    data = spring(400.0)
    data["schedule"].update(rate_max=0.5, rate_certified=False)
    return data


@pytest.fixture(scope="module")
def spring_art():
    """The spring's artifact (its rate declared uncertified) and the same law without its rate limit (sigma then
    moves as the test moves it)."""
    data = designed(_uncertified())
    free = dict(data, schedule=dict(data["schedule"], rate_max=None))
    return from_dict(data), from_dict(seal(free))


def _triangle(a: float, b: float, rate: float, Ts: float) -> np.ndarray:
    """One period: from a to b and back, ``rate * Ts`` per sample (the top clipped to b), ending at a."""
    h = rate * Ts
    n = int(np.ceil((b - a) / h - 1e-12))
    up = [min(a + k * h, b) for k in range(1, n + 1)]
    return np.array(up + up[-2::-1] + [a])


def _law_growth(art, sigma: np.ndarray, periods: int) -> tuple[float, float]:
    """The float64 scheduled law around the interpolated plant, sigma repeating ``sigma``: the plant state's norm
    after the first period and after the last."""
    from gainlink.laws.scheduled.reference import ScheduledLoop

    S = art.schedule
    loop, x, norms = ScheduledLoop(art), np.array([1e-3, 0.0]), []
    for s in np.tile(sigma, periods):
        Ad, Bd, Cd, _ = S.plant_at(s)
        x = Ad @ x + Bd @ loop.step(Cd @ x, [0.0], [s]).u
        norms.append(float(np.linalg.norm(x)))
    return norms[sigma.size - 1], norms[-1]


def _period_radius(art, sigma: np.ndarray) -> float:
    """Spectral radius of the unsaturated law and plant over one period, the transition built column by column
    from the law's step (plant x, law delta, u_prev, y_prev, e_prev; r = 0, Dd = 0), renormalised each step."""
    S = art.schedule
    _, Bd, Cd, _ = S.plant_at(sigma[0])
    n, m, p, q = Bd.shape[0], Bd.shape[1], Cd.shape[0], art.Ci.shape[0]
    nd = S.coefficients_at(sigma[0])["F"].shape[0]
    Z, log_norm = np.eye(n + nd + m + p + q), 0.0
    for s in sigma:
        Ad, Bd, Cd, Dd = S.plant_at(s)
        assert not np.any(Dd)
        c = S.coefficients_at(s)
        x, d, up, yp, ep = np.split(Z, np.cumsum([n, nd, m, p]))
        y = Cd @ x
        du = -c["Kx"] @ d - c["Ky"] @ (y - yp) - c["Kz"] @ ep
        u = up + du
        Z = np.vstack([Ad @ x + Bd @ u, c["F"] @ d + c["G"] @ du + c["Ly"] @ (y - yp), u, y, -art.Ci @ y])
        norm = np.linalg.norm(Z)
        Z, log_norm = Z / norm, log_norm + np.log(norm)
    return float(np.exp(np.log(np.max(np.abs(np.linalg.eigvals(Z)))) + log_norm))


def test_old_rate_fails_over_half_the_envelope_and_the_declared_one_holds(spring_art):
    """At the old rate the whole-envelope sweep is stable but the sweep over [0, 0.5] grows (the law itself: by
    more than 100x in 60 periods); at the declared 0.5/s the same sweep decays."""
    art, free = spring_art
    Ts, rate_max = art.Ts, art.schedule.rate_max
    assert _period_radius(art, _triangle(0.0, 1.0, OLD_RATE, Ts)) < 1.0
    half = _triangle(0.0, 0.5, OLD_RATE, Ts)
    assert _period_radius(art, half) > 1.5
    first, last = _law_growth(free, half, 60)
    assert last > 100 * first
    assert rate_max < OLD_RATE
    first, last = _law_growth(free, _triangle(0.0, 0.5, rate_max, Ts), 60)
    assert last < 1e-3 * first


def test_below_the_first_growing_rate_every_sub_range_holds(spring_art):
    """The falsifier's first growing rate is the scan's grid rate 50 * 10^-1.75 (0.89/s); at the grid rate below
    it every triangle between two points of a grid of tenths (most of them not the falsifier's nodes) is stable,
    and one grid step up some sweep of its own set grows (by the oracle here)."""
    art, _ = spring_art
    f = art.checks["schedule"]["variation"]["falsifier"]
    assert f["first_growing_rate"] == pytest.approx(50.0 * 10**-1.75)
    below = f["first_growing_rate"] / GRID_RATIO
    pairs = itertools.combinations(np.linspace(0.0, 1.0, 11), 2)
    assert max(_period_radius(art, _triangle(a, b, below, art.Ts)) for a, b in pairs) < 1.0
    w = f["worst"]
    path = Path(w["low"], w["high"], w["dwell_low"], w["dwell_high"], w["rate"], w["period"], 0.0)
    assert _period_radius(art, path.samples(art.Ts)) ** (1 / w["period"]) == pytest.approx(w["growth_per_step"])
    assert w["growth_per_step"] > 1.0


def test_the_worst_dwell_path_is_the_oracles(spring_art):
    """worst_path's dwell search (bounded screening, then eigenvalues) at a fast rate: its path, rebuilt from the
    record and multiplied out here, has the growth it reports, and no hold pair of its grid between the same levels
    grows faster by the oracle."""
    art, _ = spring_art
    L, S = loops_at(art.schedule, art.Ci), art.schedule
    dwells = dwell_grid(20.0)
    p = worst_path(L, S.points, art.Ts, 10.0, dwells)
    got = _period_radius(art, p.samples(art.Ts)) ** (1 / p.period)
    assert got == pytest.approx(p.growth, rel=1e-9)
    if p.dwell_low:
        for d1, d2 in itertools.product(dwells[::3], repeat=2):
            alt = Path(p.low, p.high, d1, d2, p.rate, 0, 0.0).samples(art.Ts)
            assert _period_radius(art, alt) ** (1 / alt.size) <= p.growth * (1 + 1e-9)


def test_shared_sweeps_equal_each_triangle_multiplied_out(spring_art):
    """The sweeps from one node share their factors; the radii equal each triangle's product taken alone."""
    art, _ = spring_art
    L, nodes = loops_at(art.schedule, art.Ci), sweep_nodes(art.schedule.points)
    assert np.allclose(nodes, np.linspace(0.0, 1.0, 9))
    for rate in (0.05, 0.9, 3.0, 45.0):
        assert np.allclose(triangle(0.0, 1.0, rate * art.Ts), _triangle(0.0, 1.0, rate, art.Ts))
        direct = [monodromy_radius(L, _triangle(a, b, rate, art.Ts)) for a, b in itertools.combinations(nodes, 2)]
        assert np.allclose(sweep_radii(L, nodes, rate * art.Ts), direct, rtol=1e-9, atol=1e-300)


def test_scan_stops_at_the_first_unstable_rate(monkeypatch):
    """Stability need not be monotone in the rate: a family growing at the sixth rate only is reported there, and
    the rates above are not tried."""
    import gainlink.laws.scheduled.rate as R

    rates = 10.0 * np.logspace(-4, 0, RATE_GRID)

    def worst(_l, points, Ts, rate, dwells, at_least=0.0):
        return Path(0.0, 1.0, 0, 0, rate, 4, 1.5 if np.isclose(rate, rates[5]) else 0.5)

    monkeypatch.setattr(R, "worst_path", worst)
    scan = scan_rates(None, np.array([0.0, 1.0]), 0.1, (1, 2))
    assert scan.unstable_rate == pytest.approx(rates[5]) and scan.rates.size == 6
