"""The falsifier of a rate verdict: periodic sigma paths at a rate rho run through the unsaturated velocity loop
(the frozen-point matrices interpolated at each sample's sigma), each judged exactly by its monodromy matrix (the
loop's transition over one period: a periodic path grows exactly when its spectral radius is at least one).

The paths at a rate:

- **triangles**: from one level to another and back at the rate, between every pair of
  :func:`~.sweeps.sweep_nodes` (the points, the envelope cut in eight, the middle of each interval);
- **dwells**: hold the lower level ``d1`` samples, ramp to the upper at the rate, hold it ``d2`` samples, ramp back
  (a jump between the levels and back when the rate crosses them in one step), between every pair of
  :func:`dwell_levels` (the points and the envelope's quarters), for ``d1``, ``d2`` on a grid from one sample to
  :data:`DWELL_TIME_CONSTANTS` closed-loop time constants (:func:`dwell_grid`). A pair whose ramp alone lasts
  longer than that grid's longest dwell is left to its triangle.

The scan (:func:`scan_rates`) tries :data:`RATE_GRID` rates over four decades below a one-step crossing of the
envelope, slow to fast, and stops at the first at which some path grows: stability is not monotone in the rate (a
periodic path is a parametric excitation), so the rates are scanned, not bisected. What it finds bounds any
certificate from above; it never certifies: rates between the grid's, other levels and dwells, non-periodic paths,
saturation and the plant's nonlinearity are not covered (docs/design.md, scheduled law).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .sweeps import product, radius, sweep_nodes, sweep_radii

RATE_GRID = 17  # rates over four decades below a one-step crossing of the envelope
DWELL_TIME_CONSTANTS = 5.0  # the longest dwell, in closed-loop time constants
DWELL_RATIO = 1.3  # the dwell grid's ratio above four samples
SCREEN_POWER = 32  # rho(M) <= |M^k|^(1/k): paths screened out below one without an eigenvalue problem


@dataclass(frozen=True)
class Path:
    """One period of a sigma path: hold ``low`` for ``dwell_low`` samples, ramp at ``rate`` to ``high``, hold it
    ``dwell_high`` samples, ramp back (a triangle: no holds). ``radius``: its monodromy matrix's spectral radius;
    ``period`` in samples."""

    low: float
    high: float
    dwell_low: int
    dwell_high: int
    rate: float
    period: int
    radius: float

    @property
    def growth(self) -> float:
        """Growth per step (above one: the loop grows along this path)."""
        return self.radius ** (1.0 / self.period) if self.radius > 0 else 0.0

    def samples(self, Ts: float) -> np.ndarray:
        """The sigma of each sample of one period (the holds first at ``low``)."""
        if self.dwell_low == 0 and self.dwell_high == 0:
            return triangle(self.low, self.high, self.rate * Ts)
        up = ramp_inside(self.low, self.high, self.rate * Ts)
        return np.concatenate([np.full(self.dwell_low, self.low), up, np.full(self.dwell_high, self.high), up[::-1]])

    def describe(self, sigma: str) -> str:
        """The path in words, for a report line."""
        if self.dwell_low or self.dwell_high:
            where = (f"held {self.dwell_low} samples at {self.low:.4g} and {self.dwell_high} at {self.high:.4g}, "
                     f"moving between them at {self.rate:.4g}/s")  # fmt: skip
        else:
            where = f"swept between {self.low:.4g} and {self.high:.4g} at {self.rate:.4g}/s"
        return f"{sigma} {where}: x{self.growth:.5f} per step"

    def to_dict(self) -> dict:
        """The record of the path."""
        return {"shape": "dwell" if self.dwell_low or self.dwell_high else "triangle", "low": self.low,
                "high": self.high, "dwell_low": self.dwell_low, "dwell_high": self.dwell_high, "rate": self.rate,
                "period": self.period, "growth_per_step": self.growth}  # fmt: skip


@dataclass(frozen=True)
class RateScan:
    """The scan: the rates tried (slow to fast, up to the first at which a path grows), the worst growth per step
    found at each (dwell paths that cannot grow are not examined, but at the last rate), the worst path at the
    last, and the dwells tried."""

    rates: np.ndarray
    growth: np.ndarray
    worst: Path
    dwells: tuple[int, ...]

    @property
    def unstable_rate(self) -> float | None:
        """The first scanned rate at which some path grows (None: none did)."""
        return float(self.rates[-1]) if self.worst.growth >= 1.0 else None


def ramp_inside(a: float, b: float, step: float) -> np.ndarray:
    """The samples strictly between ``a`` and ``b`` on the way up at ``step`` per sample."""
    k = max(1, int(np.ceil((b - a) / step - 1e-12)))
    return a + step * np.arange(1, k)


def triangle(a: float, b: float, step: float) -> np.ndarray:
    """One period of the triangle between ``a`` and ``b`` at ``step`` per sample (the top clipped to ``b``)."""
    k = max(1, int(np.ceil((b - a) / step)))
    up = np.minimum(a + step * np.arange(1, k + 1), b)
    return np.concatenate([up, up[::-1][1:], [a]])


def dwell_grid(tau_samples: float) -> tuple[int, ...]:
    """Dwells from one sample to :data:`DWELL_TIME_CONSTANTS` time constants: 1 to 4, then :data:`DWELL_RATIO`."""
    longest = max(4, int(np.ceil(DWELL_TIME_CONSTANTS * tau_samples)))
    grid = [1, 2, 3, 4]
    while grid[-1] < longest:
        grid.append(min(longest, max(grid[-1] + 1, int(round(grid[-1] * DWELL_RATIO)))))
    return tuple(grid)


def monodromy_radius(loops_at: Callable[[np.ndarray], np.ndarray], sigma: np.ndarray) -> float:
    """Spectral radius of the loop's transition over one period: ``loops_at(sigma)`` gives the (K, N, N) matrices
    of the steps, multiplied in pairs level by level, each product renormalised (its log-norm kept aside)."""
    return radius(*product(loops_at(np.asarray(sigma, dtype=float))))


def dwell_levels(points: np.ndarray) -> np.ndarray:
    """The levels of the dwell paths: the schedule's points and the envelope's quarters (sorted, no repeats)."""
    pts = np.asarray(points, dtype=float)
    levels = np.unique(np.concatenate([pts, np.linspace(pts[0], pts[-1], 5)]))
    return levels[np.concatenate([[True], np.diff(levels) > 1e-9 * (pts[-1] - pts[0])])]


def worst_path(loops_at, points: np.ndarray, Ts: float, rate: float, dwells: tuple[int, ...], *,
               at_least: float = 0.0) -> Path:  # fmt: skip
    """The path of largest growth per step at ``rate``: triangles between every pair of
    :func:`~.sweeps.sweep_nodes`, dwells between every pair of :func:`dwell_levels`. Dwell paths that
    cannot grow by ``at_least`` per step are not examined: the answer is exact when the worst grows at least that
    much (the scan asks for 1: is there a growing path?)."""
    nodes = sweep_nodes(points)
    step = rate * Ts
    pairs = list(itertools.combinations(nodes.tolist(), 2))
    radii = sweep_radii(loops_at, nodes, step)
    tri = [Path(a, b, 0, 0, rate, triangle(a, b, step).size, float(r)) for (a, b), r in zip(pairs, radii)]
    best = max(tri, key=lambda p: p.growth)
    levels = dwell_levels(points)
    powers = dict(zip(levels.tolist(), (_powers(A, dwells) for A in loops_at(levels))))
    for a, b in itertools.combinations(levels.tolist(), 2):
        if ramp_inside(a, b, step).size <= dwells[-1]:
            best = _dwell_worst(loops_at, (a, b), (powers[a], powers[b]), rate, step, dwells, best, at_least)
    return best


def _dwell_worst(loops_at, ends: tuple[float, float], powers: tuple[np.ndarray, np.ndarray], rate: float,
                 step: float, dwells: tuple[int, ...], best: Path, at_least: float) -> Path:  # fmt: skip
    """The dwell paths between ``ends``: ``best`` or the one growing faster. The monodromy matrix of ``(d1, d2)`` is
    ``Down A_b^d2 Up A_a^d1`` (``powers``: each end's ``A^d`` for the dwells); its spectral radius is bounded by
    ``|M^k|^(1/k)`` first, and only paths that bound cannot rule out get an eigenvalue problem."""
    a, b = ends
    Pa, Pb = powers
    inside = ramp_inside(a, b, step)
    if inside.size:
        (up, up_log), (down, down_log) = product(loops_at(inside)), product(loops_at(inside[::-1]))
    else:
        up, up_log, down, down_log = np.eye(Pa.shape[1]), 0.0, np.eye(Pa.shape[1]), 0.0
    M = (down[None] @ Pb @ up[None])[None, :] @ Pa[:, None]  # (D1, D2, N, N)
    d = np.asarray(dwells)
    period = d[:, None] + d[None, :] + 2 * inside.size
    logs = up_log + down_log
    bound = _radius_bound(M.reshape(-1, *M.shape[2:]), logs).reshape(period.shape) ** (1.0 / period)
    for i, j in zip(*np.unravel_index(np.argsort(-bound, axis=None, kind="stable"), bound.shape)):
        if bound[i, j] <= max(best.growth, at_least):
            break
        cand = Path(a, b, int(d[i]), int(d[j]), rate, int(period[i, j]), radius(M[i, j], logs))
        if cand.growth > best.growth:
            best = cand
    return best


def _powers(A: np.ndarray, dwells: tuple[int, ...]) -> np.ndarray:
    """``A^d`` for each dwell (increasing), one matrix power per step of the grid."""
    out, prev, cur = [], 0, np.eye(A.shape[0])
    for d in dwells:
        cur = np.linalg.matrix_power(A, d - prev) @ cur
        out.append(cur)
        prev = d
    return np.array(out)


def _radius_bound(M: np.ndarray, log_scale: float) -> np.ndarray:
    """``exp(log_scale) |M^k|_F^(1/k)`` for each matrix of the stack (k = :data:`SCREEN_POWER`): an upper bound
    of the spectral radius of ``exp(log_scale) M``."""
    mats, logs = M.copy(), np.zeros(M.shape[0])
    for _ in range(int(np.log2(SCREEN_POWER))):
        norms = np.linalg.norm(mats, axis=(1, 2))
        safe = np.where(norms > 0, norms, 1.0)
        mats = mats / safe[:, None, None]
        logs = 2 * (logs + np.log(safe))
        mats = mats @ mats
    logs = logs + np.log(np.maximum(np.linalg.norm(mats, axis=(1, 2)), 1e-300))
    return np.exp(np.minimum(logs / SCREEN_POWER + log_scale, 700.0))


def scan_rates(loops_at, points: np.ndarray, Ts: float, dwells: tuple[int, ...]) -> RateScan:
    """Scan :data:`RATE_GRID` rates from slow to fast; stop at the first at which some path grows (when none does,
    the worst path at the fastest rate)."""
    span = float(points[-1] - points[0])
    rates = span / Ts * np.logspace(-4, 0, RATE_GRID)
    growth: list[float] = []
    for rate in rates:
        worst = worst_path(loops_at, points, Ts, float(rate), dwells, at_least=1.0)
        growth.append(worst.growth)
        if worst.growth >= 1.0:
            return RateScan(rates[: len(growth)], np.array(growth), worst, dwells)
    worst = worst_path(loops_at, points, Ts, float(rates[-1]), dwells)  # nothing grows: the worst at the fastest
    growth[-1] = worst.growth
    return RateScan(rates, np.array(growth), worst, dwells)
