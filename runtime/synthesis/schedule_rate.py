"""How fast sigma may move, found by simulation: the velocity loop driven by periodic sigma trajectories at a
rate rho (ramps across the whole envelope and across each interval, and rate-limited steps that dwell at the
ends), each judged exactly by its monodromy matrix (the loop's transition over one period: the periodic system
is stable exactly when its spectral radius is below one).

Rates are scanned from slow to fast on a log grid; the answer is the fastest rate below which every rate tested
was stable (None when every rate was, up to sigma crossing the whole envelope in one step). It confirms a
certificate; it does not replace one (docs/design.md, scheduled law).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

RATE_GRID = 17  # rates over four decades below a one-step crossing of the envelope
DWELLS = (1, 25)  # samples held at each end of a rate-limited step


@dataclass(frozen=True)
class RateScan:
    """The scan: the rates tried (slow to fast), the worst monodromy spectral radius at each, and the fastest
    rate below which all were stable (None: all were)."""

    rates: np.ndarray
    radius: np.ndarray
    stable_rate: float | None


def trajectories(points: np.ndarray, step: float) -> list[np.ndarray]:
    """One period of each periodic sigma trajectory at ``step`` per sample."""
    lo, hi = float(points[0]), float(points[-1])
    out = [_triangle(lo, hi, step)]
    out += [_triangle(float(a), float(b), step) for a, b in itertools.pairwise(points)]
    for dwell in DWELLS:
        up = _ramp(lo, hi, step)
        out.append(np.concatenate([np.full(dwell, lo), up, np.full(dwell, hi), up[::-1]]))
    return out


def _ramp(a: float, b: float, step: float) -> np.ndarray:
    k = max(1, int(np.ceil((b - a) / step)))
    return np.minimum(a + step * np.arange(1, k + 1), b)


def _triangle(a: float, b: float, step: float) -> np.ndarray:
    up = _ramp(a, b, step)
    return np.concatenate([up, _ramp(a, b, step)[::-1][1:], [a]])


def monodromy_radius(loops_at: Callable[[np.ndarray], np.ndarray], sigma: np.ndarray) -> float:
    """Spectral radius of the loop's transition over one period: ``loops_at(sigma)`` gives the (K, N, N) matrices
    of the steps, multiplied in pairs level by level, each product renormalised (its log-norm kept aside)."""
    mats = loops_at(np.asarray(sigma, dtype=float))
    log_scale = 0.0
    while mats.shape[0] > 1:
        if mats.shape[0] % 2:
            mats = np.concatenate([mats, np.eye(mats.shape[1])[None]])
        mats = mats[1::2] @ mats[0::2]  # later steps on the left
        norms = np.linalg.norm(mats, axis=(1, 2))
        if np.any(norms == 0.0):
            return 0.0
        mats = mats / norms[:, None, None]
        log_scale += float(np.sum(np.log(norms)))
    rho = float(np.max(np.abs(np.linalg.eigvals(mats[0]))))
    return 0.0 if rho == 0.0 else float(np.exp(min(np.log(rho) + log_scale, 700.0)))


def scan_rates(loops_at: Callable[[np.ndarray], np.ndarray], points: np.ndarray, Ts: float) -> RateScan:
    """Scan rates from slow to fast; stop at the first whose trajectories are not all stable."""
    span = float(points[-1] - points[0])
    fastest = span / Ts  # the whole envelope in one step
    rates = fastest * np.logspace(-4, 0, RATE_GRID)
    radius = []
    for rate in rates:
        worst = max(monodromy_radius(loops_at, traj) for traj in trajectories(points, rate * Ts))
        radius.append(worst)
        if not worst < 1.0:
            stable = float(rates[len(radius) - 2]) if len(radius) > 1 else 0.0
            return RateScan(rates[: len(radius)], np.array(radius), stable)
    return RateScan(rates, np.array(radius), None)
