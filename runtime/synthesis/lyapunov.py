"""Stability of the scheduled loop while sigma moves: quadratic Lyapunov functions found as LMIs (solved by
Clarabel, SCS as the fallback, :mod:`.lmi`) and re-checked by eigenvalues in float64.

The velocity loop on an interval is a matrix polynomial in lambda (:mod:`.lpv`), not affine, so a Lyapunov matrix
that works at the points proves nothing between them (docs/design.md). Its Bernstein coefficients on each interval
(split in ``pieces`` parts for a tighter hull) are vertices whose convex hull holds the loop's matrix for every
sigma there. ``A' P A`` is convex in ``A`` for ``P >= 0``, so ``V' P V < P`` at every vertex gives it for every
sigma:

- **any rate**: one ``P`` for every vertex of every interval (:func:`common_lyapunov`);
- **a rate**: ``P(sigma)`` piecewise linear between nodes, with ``V' P(s') V < P(s)`` for every vertex of the piece
  holding ``s`` and every ``s'`` with ``|s' - s| <= Ts rho`` (:func:`rate_certificate`). The condition is affine in
  ``(s, s')`` on each pair of pieces, so it is imposed at the vertices of each such polygon; bisection on rho.

Every certificate is re-checked here with ``numpy.linalg.eigvalsh`` on the vertices (a solver's "optimal" is not
the verdict); a solver that fails outright raises :class:`DesignError` in one line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .lmi import LmiFamily

#: Relative margin a re-checked certificate must keep: ``eig(P - V' P V) >= MARGIN * eig_max(P)``.
MARGIN = 1e-9
BISECTION_STEPS = 6


@dataclass(frozen=True)
class Certificate:
    """A re-checked Lyapunov certificate: node sigmas and ``P`` at each (one node for a common ``P``), the rate
    it holds for (None: any rate), the smallest relative margin found by the re-check, and the solver."""

    nodes: np.ndarray
    P: list[np.ndarray]
    rate: float | None
    margin: float
    solver: str


def common_lyapunov(vertices: list[np.ndarray]) -> Certificate | None:
    """One ``P`` with ``V' P V < P`` for every vertex, re-checked; None when the LMI has no solution."""
    lmi = LmiFamily(N=vertices[0].shape[0], nodes=1)
    for V in vertices:
        lmi.decrease(np.ones(1), np.ones(1), V)
    checks = lambda Ps: [(Ps[0], Ps[0], V) for V in vertices]  # noqa: E731
    Ps, solver = lmi.solve(proves=lambda Ps: _recheck(checks(Ps)) is not None)
    if Ps is None:
        return None
    margin = _recheck(checks(Ps))
    return None if margin is None else Certificate(np.zeros(1), Ps, None, margin, solver)


def rate_certificate(nodes: np.ndarray, vertices_by_piece: list[list[np.ndarray]], *, Ts: float,
                     rate_hi: float) -> Certificate | None:  # fmt: skip
    """The largest rate below ``rate_hi`` (bisection on a log scale over three decades, :data:`BISECTION_STEPS`
    steps) for which a piecewise-linear ``P(sigma)`` certifies the loop; None when none does even for a frozen
    sigma. ``rate_hi`` is best a rate known to be unstable (the simulated scan's first): nothing above it can be
    certified."""
    attempt = lambda rate: _rate_attempt(nodes, vertices_by_piece, Ts * rate, rate)  # noqa: E731
    best = attempt(0.0)
    if best is None:
        return None
    lo, hi = np.log(rate_hi) - np.log(1e3), np.log(rate_hi)
    if (first := attempt(float(np.exp(lo)))) is None:
        return best
    best = first
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        cert = attempt(float(np.exp(mid)))
        if cert is not None:
            best, lo = cert, mid
        else:
            hi = mid
    return best


def _rate_attempt(nodes, vertices_by_piece, step: float, rate: float) -> Certificate | None:
    corners = [(j, s, s2) for j, _k, pts in _piece_pairs(nodes, step) for s, s2 in pts]
    lmi = LmiFamily(N=vertices_by_piece[0][0].shape[0], nodes=len(nodes))
    for j, s, s2 in corners:
        for V in vertices_by_piece[j]:
            lmi.decrease(_weights(nodes, s), _weights(nodes, s2), V)

    def checks(Ps: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        at = lambda s: sum(w * P for w, P in zip(_weights(nodes, s), Ps))  # noqa: E731
        return [(at(s), at(s2), V) for j, s, s2 in corners for V in vertices_by_piece[j]]

    Ps, solver = lmi.solve(proves=lambda Ps: _recheck(checks(Ps)) is not None)
    if Ps is None:
        return None
    margin = _recheck(checks(Ps))
    return None if margin is None else Certificate(nodes, Ps, rate, margin, solver)


def _weights(nodes: np.ndarray, s: float) -> np.ndarray:
    """The node weights of ``P(s)``: linear between the two nodes around s."""
    w = np.zeros(len(nodes))
    j = int(np.clip(np.searchsorted(nodes, s, side="right") - 1, 0, len(nodes) - 2))
    t = float((s - nodes[j]) / (nodes[j + 1] - nodes[j]))
    w[j], w[j + 1] = 1.0 - t, t
    return w


def _piece_pairs(nodes: np.ndarray, step: float) -> list[tuple[int, int, list[tuple[float, float]]]]:
    """For each piece j (sigma there) and piece k (sigma' there) within ``step`` of each other, the vertices of
    ``{s in piece j, s' in piece k, |s' - s| <= step}``."""
    out = []
    K = len(nodes) - 1
    for j in range(K):
        for k in range(K):
            corners = _polygon(nodes[j], nodes[j + 1], nodes[k], nodes[k + 1], step)
            if corners:
                out.append((j, k, corners))
    return out


def _polygon(a: float, b: float, c: float, d: float, step: float) -> list[tuple[float, float]]:
    """Vertices of ``[a, b] x [c, d]`` cut by ``|s' - s| <= step`` (empty when they do not meet)."""
    cand = [(a, c), (a, d), (b, c), (b, d)]
    for sign in (-1.0, 1.0):  # lines s' = s + sign step against the box's edges
        cand += [(a, a + sign * step), (b, b + sign * step), (c - sign * step, c), (d - sign * step, d)]
    tol = 1e-12 * max(1.0, abs(a), abs(d))
    keep = []
    for s, s2 in cand:
        inside = a - tol <= s <= b + tol and c - tol <= s2 <= d + tol and abs(s2 - s) <= step + tol
        if inside and all(abs(s - u) > tol or abs(s2 - v) > tol for u, v in keep):
            keep.append((float(np.clip(s, a, b)), float(np.clip(s2, c, d))))
    return keep


def _recheck(checks: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> float | None:
    """The smallest ``eig_min(P_s - V' P_s2 V) / eig_max(P_s)`` over the checks, None when any is below
    :data:`MARGIN` or a ``P`` is not positive definite."""
    worst = np.inf
    for P_s, P_s2, V in checks:
        top = float(np.linalg.eigvalsh(P_s)[-1])
        if np.linalg.eigvalsh(P_s)[0] <= 0 or np.linalg.eigvalsh(P_s2)[0] <= 0:
            return None
        D = P_s - V.T @ P_s2 @ V
        worst = min(worst, float(np.linalg.eigvalsh((D + D.T) / 2)[0]) / top)
    return worst if worst >= MARGIN else None
