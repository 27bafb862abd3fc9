"""How fast sigma may move, found by simulation: the velocity loop (the frozen-point matrices interpolated at each
sample's sigma, no saturation) driven by periodic sigma trajectories at a rate rho, each judged exactly by its
monodromy matrix (the loop's transition over one period: the periodic system is stable exactly when its spectral
radius is below one).

The trajectories at a rate (:func:`trajectories`): a triangle between every pair of :func:`sweep_nodes` (the
schedule's points, the envelope cut in eight, the middle of each interval), so periodic sweeps over the whole
envelope, over each interval and over every sub-range on that grid, within an interval or across; and rate-limited
steps across the whole envelope that dwell 1 and 25 samples at its ends. Stability is not monotone in the rate (a
sweep's period is a parametric excitation: the example spring is unstable over half its envelope at 1.6/s and
stable there at 4.7/s), so rates are not bisected: they are scanned from slow to fast on a fixed log grid
(:data:`RATE_GRID` rates over four decades below a one-step crossing of the envelope) and the answer is the fastest
scanned rate below which every scanned rate was stable (None when every rate was).

What that covers: those trajectories at those rates, in the linear loop. What it does not: rates between the grid's
(a resonance narrower than one grid ratio, 10^(1/4), could be missed), sweeps whose ends are not on the node grid,
other shapes (several ranges in turn, non-periodic motion), saturation and the plant's nonlinearity. It confirms a
certificate; it does not replace one (docs/design.md, scheduled law).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .schedule_sweeps import product, radius, sweep_nodes, sweep_radii

RATE_GRID = 17  # rates over four decades below a one-step crossing of the envelope
DWELLS = (1, 25)  # samples held at each end of a rate-limited step


@dataclass(frozen=True)
class RateScan:
    """The scan: the rates tried (slow to fast, up to the first unstable one), the worst monodromy spectral radius
    at each, and the fastest rate at and below which all tried were stable (None: all were)."""

    rates: np.ndarray
    radius: np.ndarray
    stable_rate: float | None


def trajectories(points: np.ndarray, step: float) -> list[np.ndarray]:
    """One period of each periodic sigma trajectory at ``step`` per sample: first the triangle over the whole
    envelope, then a triangle between every other pair of :func:`sweep_nodes` (every sub-range on that grid,
    within an interval and across), then the rate-limited steps across the envelope that dwell at its ends."""
    lo, hi = float(points[0]), float(points[-1])
    out = [_triangle(lo, hi, step)]
    pairs = itertools.combinations(sweep_nodes(points), 2)
    out += [_triangle(float(a), float(b), step) for a, b in pairs if (a, b) != (lo, hi)]
    return out + dwell_steps(points, step)


def dwell_steps(points: np.ndarray, step: float) -> list[np.ndarray]:
    """One period of each rate-limited step across the envelope that dwells :data:`DWELLS` samples at its ends."""
    lo, hi = float(points[0]), float(points[-1])
    up = _ramp(lo, hi, step)
    return [np.concatenate([np.full(d, lo), up, np.full(d, hi), up[::-1]]) for d in DWELLS]


def _ramp(a: float, b: float, step: float) -> np.ndarray:
    k = max(1, int(np.ceil((b - a) / step)))
    return np.minimum(a + step * np.arange(1, k + 1), b)


def _triangle(a: float, b: float, step: float) -> np.ndarray:
    up = _ramp(a, b, step)
    return np.concatenate([up, _ramp(a, b, step)[::-1][1:], [a]])


def monodromy_radius(loops_at: Callable[[np.ndarray], np.ndarray], sigma: np.ndarray) -> float:
    """Spectral radius of the loop's transition over one period: ``loops_at(sigma)`` gives the (K, N, N) matrices
    of the steps, multiplied in pairs level by level, each product renormalised (its log-norm kept aside)."""
    return radius(*product(loops_at(np.asarray(sigma, dtype=float))))


def scan_rates(loops_at: Callable[[np.ndarray], np.ndarray], points: np.ndarray, Ts: float) -> RateScan:
    """Scan :data:`RATE_GRID` rates from slow to fast; stop at the first at which some trajectory is not stable:
    ``stable_rate`` is the rate before it (every scanned rate up to it stable; 0 when the slowest is not), whatever
    faster rates would give."""
    span = float(points[-1] - points[0])
    fastest = span / Ts  # the whole envelope in one step
    rates = fastest * np.logspace(-4, 0, RATE_GRID)
    radius = []
    for rate in rates:
        step = rate * Ts
        steps = [monodromy_radius(loops_at, traj) for traj in dwell_steps(points, step)]
        worst = max(float(np.max(sweep_radii(loops_at, sweep_nodes(points), step))), *steps)
        radius.append(worst)
        if not worst < 1.0:
            stable = float(rates[len(radius) - 2]) if len(radius) > 1 else 0.0
            return RateScan(rates[: len(radius)], np.array(radius), stable)
    return RateScan(rates, np.array(radius), None)
