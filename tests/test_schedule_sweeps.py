"""The simulated rate covers periodic sweeps over sub-ranges of the envelope (issue 18, item 3).

On the spring of ``schedule_cases`` (no Lyapunov certificate, so the simulated rate is ``rate_max``), the rate the
verdict gave when it swept only the whole envelope and each interval, 50 * 10^(-1.5) = 1.58/s, does not hold for a
sweep over half the envelope. The oracles are the test's own: the float64 scheduled law
(``gainlink.proof.scheduled_reference``) around the interpolated plant, and a transition matrix over one period built
here from the law's step equations (docs/design.md), both stepped sample by sample on triangles made here.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from gainlink.shipping.artifact import from_dict, seal
from gainlink.spec import parse_spec
from gainlink.synthesis import synthesize
from gainlink.synthesis.schedule_rate import RATE_GRID, monodromy_radius, scan_rates, trajectories
from gainlink.synthesis.schedule_sweeps import sweep_nodes, sweep_radii
from gainlink.synthesis.schedule_variation import loops_at
from schedule_cases import spring

OLD_RATE = 50.0 * 10**-1.5  # the old verdict: the scan's grid rate before the first full-envelope instability
GRID_RATIO = 10 ** (4 / (RATE_GRID - 1))


@pytest.fixture(scope="module")
def spring_art():
    """The spring's artifact and the same law without its rate limit (sigma then moves as the test moves it)."""
    result = synthesize(parse_spec(spring()))
    free = dict(result.artifact, schedule=dict(result.artifact["schedule"], rate_max=None))
    return from_dict(result.artifact), from_dict(seal(free))


def _triangle(a: float, b: float, rate: float, Ts: float) -> np.ndarray:
    """One period: from a to b and back, ``rate * Ts`` per sample (the top clipped to b), ending at a."""
    h = rate * Ts
    n = int(np.ceil((b - a) / h - 1e-12))
    up = [min(a + k * h, b) for k in range(1, n + 1)]
    return np.array(up + up[-2::-1] + [a])


def _law_growth(art, sigma: np.ndarray, periods: int) -> tuple[float, float]:
    """The float64 scheduled law around the interpolated plant, sigma repeating ``sigma``: the plant state's norm
    after the first period and after the last."""
    from gainlink.proof.scheduled_reference import ScheduledLoop

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


def test_old_rate_fails_over_half_the_envelope_and_the_new_one_holds(spring_art):
    """At the old rate the whole-envelope sweep is stable but the sweep over [0, 0.5] grows (the law itself: by
    more than 100x in 60 periods); the verdict's rate_max is now below it, and there the same sweep decays."""
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


def test_new_rate_holds_for_every_sub_range(spring_art):
    """rate_max is the scan's grid rate 50 * 10^-2 (the first instability is one grid step up), and at it every
    triangle between two points of a grid of tenths (most of them not the verdict's nodes) is stable."""
    art, _ = spring_art
    v = art.checks["schedule"]["variation"]
    assert v["rate_max_source"].startswith("simulation")
    assert art.schedule.rate_max == v["simulated_stable_rate"] == pytest.approx(50.0 * 10**-2)
    pairs = itertools.combinations(np.linspace(0.0, 1.0, 11), 2)
    radii = [_period_radius(art, _triangle(a, b, art.schedule.rate_max, art.Ts)) for a, b in pairs]
    assert max(radii) < 1.0


def test_rate_max_is_not_vacuous(spring_art):
    """One grid step above rate_max some sweep of the verdict's own set is unstable (by the oracle here); at
    rate_max none is."""
    art, _ = spring_art
    pairs = list(itertools.combinations(sweep_nodes(art.schedule.points), 2))
    worst = max(_period_radius(art, _triangle(a, b, art.schedule.rate_max * GRID_RATIO, art.Ts)) for a, b in pairs)
    assert worst > 1.0
    assert max(_period_radius(art, _triangle(a, b, art.schedule.rate_max, art.Ts)) for a, b in pairs) < 1.0


def test_shared_sweeps_equal_each_triangle_multiplied_out(spring_art):
    """The sweeps from one node share their factors; the radii equal each triangle's product taken alone, and
    the trajectory list holds one triangle per pair of nodes (whole envelope first) and the two dwelling steps."""
    art, _ = spring_art
    L, nodes = loops_at(art.schedule, art.Ci), sweep_nodes(art.schedule.points)
    assert np.allclose(nodes, np.linspace(0.0, 1.0, 9))
    for rate in (0.05, 0.9, 3.0, 45.0):
        trajs = trajectories(art.schedule.points, rate * art.Ts)
        assert len(trajs) == 36 + 2 and np.allclose(trajs[0], _triangle(0.0, 1.0, rate, art.Ts))
        direct = [monodromy_radius(L, _triangle(a, b, rate, art.Ts)) for a, b in itertools.combinations(nodes, 2)]
        assert np.allclose(sweep_radii(L, nodes, rate * art.Ts), direct, rtol=1e-9, atol=1e-300)


def test_scan_stops_at_the_first_unstable_rate(monkeypatch):
    """Stability need not be monotone in the rate: a family unstable at the sixth rate only gives the fifth rate,
    and the rates above are not tried."""
    import gainlink.synthesis.schedule_rate as R

    rates = 10.0 * np.logspace(-4, 0, RATE_GRID)
    bad = rates[5] * 0.1  # the step at the sixth rate (Ts = 0.1)
    monkeypatch.setattr(R, "sweep_radii", lambda _l, nodes, step: np.array([2.0 if np.isclose(step, bad) else 0.5]))
    monkeypatch.setattr(R, "monodromy_radius", lambda _l, _s: 0.5)
    scan = scan_rates(None, np.array([0.0, 1.0]), 0.1)
    assert scan.stable_rate == pytest.approx(rates[4]) and scan.rates.size == 6
