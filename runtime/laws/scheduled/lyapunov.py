"""Stability of the scheduled loop while sigma moves: quadratic Lyapunov functions found as LMIs (:mod:`.lmi`) on the
pieces of :mod:`.hull`, and proved in ball arithmetic.

The loop's matrix on a piece lies in the convex hull of the piece's Bernstein vertices ``V``. ``A' P A`` is convex
in ``A`` for ``P >= 0``, so ``P(s) - V' P(s') V > 0`` at every vertex gives ``P(s) - A(s)' P(s') A(s) > 0`` for the
loop itself. Three certificates use it:

- **frozen** (rate 0): one ``P`` per piece with ``P - V' P V > 0`` at its vertices: the loop frozen at any sigma of
  the piece is stable (:func:`frozen_piece`);
- **any rate**: one ``P`` for every vertex of every piece (:func:`common_certificate`);
- **a rate** rho: ``P(sigma)`` piecewise linear between nodes (a coarser partition than the pieces), with
  ``P(s) - V' P(s') V > 0`` for every vertex of the piece holding ``s`` and every ``s'`` with ``|s' - s| <= Ts
  rho`` (:func:`rate_attempt`). On a piece and a node interval the condition is affine in ``(s, s')``, so it is
  imposed at the corners of each such polygon; then ``x' P(sigma_k) x`` decreases along every sigma path whose
  steps are at most ``Ts rho`` (the standard bounded-rate parameter-dependent Lyapunov argument).

A solver's answer is a candidate. :func:`prove` re-checks every inequality at the exact corners (rational sigmas,
``h = Ts rho`` exact) on ball enclosures of the exact vertices of the artifact's float64 matrices, at
:data:`PREC` bits: each ``P`` node and each ``P(s) - V' P(s') V`` is proved positive definite by Rump's test
(:func:`~.balls.verified_lambda_min`). Only a proved certificate is returned.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from math import comb

import numpy as np
import scipy.linalg

from ...synthesis.balls import verified_lambda_min
from ...synthesis.lmi import LmiFamily, LmiSolution
from .hull import Basis, LoopHull, Piece

PREC = 128  # bits of the re-check's ball arithmetic
REWHITEN = 2  # re-solves of an LMI in the basis its own solution whitens (module docstring of .hull)


@dataclass(frozen=True)
class Certificate:
    """A proved Lyapunov certificate. ``kind``: ``frozen`` (``P[j]`` on ``[nodes[j], nodes[j+1]]``, sigma fixed),
    ``common`` (one ``P``, any rate) or ``rate`` (``P`` linear between ``nodes``, ``|d sigma| <= Ts rate``). ``margin``:
    a proved lower bound of ``min eig(P(s) - V' P(s') V) / max |P|_F`` over its ``inequalities``; ``pieces``: the
    hull's pieces; ``solver``: who found it."""

    kind: str
    nodes: tuple[Fraction, ...]
    P: tuple[np.ndarray, ...]
    rate: float | None
    margin: float
    solver: str
    pieces: int
    inequalities: int

    def to_dict(self) -> dict:
        """The record of the matrices (so that anyone can re-check them) and what they prove."""
        return {
            "kind": self.kind,
            "nodes": [float(v) for v in self.nodes],
            "P": [[[float(x) for x in row] for row in P] for P in self.P],
            "rate": self.rate,
            "margin": self.margin,
            "solver": self.solver,
            "hull_pieces": self.pieces,
            "inequalities": self.inequalities,
        }


@dataclass(frozen=True)
class Attempt:
    """One LMI solved and re-checked: the certificate (None: not proved), the solver's ``mu``, and each piece's and
    each node interval's share of the dual (where the inequalities bind; each sums to one)."""

    certificate: Certificate | None
    mu: float
    piece_weights: np.ndarray
    node_weights: np.ndarray
    rate: float | None = None


# A check: (P(s) as node weights, P(s') as node weights, index of the piece whose vertices apply)
Check = tuple[dict[int, Fraction], dict[int, Fraction], int]


def frozen_piece(hull: LoopHull, piece: Piece) -> Attempt:
    """One ``P`` for the loop frozen anywhere on ``piece`` (solved in a basis whitened at the piece's middle)."""
    d = len(piece.vertices) - 1
    A_mid = sum(comb(d, k) * 0.5**d * V for k, V in enumerate(piece.vertices))  # the Bernstein form at t = 1/2
    X = scipy.linalg.solve_discrete_lyapunov(A_mid.T, np.eye(hull.N))
    w, Q = np.linalg.eigh(0.5 * (X + X.T))
    if not np.all(w > 0):
        return Attempt(None, -np.inf, np.ones(1), np.ones(1))

    def fill(lmi: LmiFamily, basis: Basis) -> None:
        for V in piece.vertices:
            lmi.decrease(np.ones(1), np.ones(1), basis.apply(V))

    sol, Ps = _solve(hull, fill, 1, Basis(Q @ np.diag(w**-0.5)))
    checks = [({0: Fraction(1)}, {0: Fraction(1)}, 0)]
    return _attempt(hull, [piece], "frozen", (piece.lo, piece.hi), Ps, checks, None, sol)


def common_certificate(hull: LoopHull, pieces: list[Piece]) -> Attempt:
    """One ``P`` for every vertex of every piece: stable whatever sigma does."""

    def fill(lmi: LmiFamily, basis: Basis) -> None:
        for p in pieces:
            for V, T in hull.lmi_vertices(p, basis):
                lmi.decrease(np.ones(1), np.ones(1), V, T)

    sol, Ps = _solve(hull, fill, 1, hull.basis)
    checks = [({0: Fraction(1)}, {0: Fraction(1)}, j) for j in range(len(pieces))]
    return _attempt(hull, pieces, "common", (hull.points[0],), Ps, checks, None, sol)


def rate_attempt(hull: LoopHull, pieces: list[Piece], nodes: list[Fraction], *, step: Fraction,
                 rate: float) -> Attempt:  # fmt: skip
    """``P(sigma)`` linear between ``nodes`` (each piece within one node interval) for ``|d sigma| <= step`` per
    sample, ``rate = step / Ts``."""
    checks = rate_checks(pieces, nodes, step)

    def fill(lmi: LmiFamily, basis: Basis) -> None:
        for wa, wb, j in checks:
            a, b = _dense(wa, len(nodes)), _dense(wb, len(nodes))
            for V, T in hull.lmi_vertices(pieces[j], basis):
                lmi.decrease(a, b, V, T)

    sol, Ps = _solve(hull, fill, len(nodes), hull.basis)
    return _attempt(hull, pieces, "rate", tuple(nodes), Ps, checks, rate, sol)


def _solve(hull: LoopHull, fill, nodes: int, basis: Basis) -> tuple[LmiSolution, list[np.ndarray]]:
    """The LMI ``fill(lmi, basis)`` builds, solved in ``basis`` (within the hull's scaled one). When it holds no
    margin and its ``P`` presses the bound on the condition number, it is solved again in the basis that ``P``
    whitens (:data:`REWHITEN` times at most), and that basis is kept (``basis`` takes it: the hull's own, for every
    later LMI) only when it proves what the first could not. Returns the solution and its ``P`` in the loop's
    coordinates."""
    trial, first = basis, None
    for rebased in range(REWHITEN + 1):
        lmi = LmiFamily(N=hull.N, nodes=nodes)
        fill(lmi, trial)
        sol = lmi.solve()
        if sol.mu > 0:
            basis.W, basis.version = trial.W, trial.version
            return sol, [hull.from_scaled(trial.back(P)) for P in sol.P]
        first = first or (sol, [hull.from_scaled(trial.back(P)) for P in sol.P])
        if rebased == REWHITEN or max(float(np.linalg.eigvalsh(P)[-1]) for P in sol.P) <= 0.5 * lmi.cap:
            break
        trial = trial.copy()
        trial.rebase(sol.P)
    return first


def rate_checks(pieces: list[Piece], nodes: list[Fraction], step: Fraction) -> list[Check]:
    """The corners ``(s, s')`` (as node weights) of every piece against every node interval within ``step``."""
    out: list[Check] = []
    for j, p in enumerate(pieces):
        corners: list[tuple[Fraction, Fraction]] = []
        for k in range(len(nodes) - 1):
            if nodes[k] - step >= p.hi or nodes[k + 1] + step <= p.lo:
                continue
            corners += [c for c in polygon(p.lo, p.hi, nodes[k], nodes[k + 1], step) if c not in corners]
        out += [(node_weights(nodes, s), node_weights(nodes, s2), j) for s, s2 in corners]
    return out


def polygon(a: Fraction, b: Fraction, c: Fraction, d: Fraction, step: Fraction) -> list[tuple[Fraction, Fraction]]:
    """Vertices of ``[a, b] x [c, d]`` cut by ``|s' - s| <= step`` (exact; empty when they do not meet)."""
    cand = [(a, c), (a, d), (b, c), (b, d)]
    for sign in (-1, 1):  # the lines s' = s + sign step against the box's edges
        cand += [(a, a + sign * step), (b, b + sign * step), (c - sign * step, c), (d - sign * step, d)]
    keep: list[tuple[Fraction, Fraction]] = []
    for s, s2 in cand:
        if a <= s <= b and c <= s2 <= d and abs(s2 - s) <= step and (s, s2) not in keep:
            keep.append((s, s2))
    return keep


def node_weights(nodes: list[Fraction], s: Fraction) -> dict[int, Fraction]:
    """The weights of ``P(s)`` on the nodes around ``s`` (linear between them; exact)."""
    k = max(0, min(len(nodes) - 2, next((i for i in range(len(nodes) - 1) if s < nodes[i + 1]), len(nodes) - 2)))
    t = (s - nodes[k]) / (nodes[k + 1] - nodes[k])
    return {i: w for i, w in ((k, 1 - t), (k + 1, t)) if w != 0}


def _dense(w: dict[int, Fraction], size: int) -> np.ndarray:
    out = np.zeros(size)
    for k, v in w.items():
        out[k] = float(v)
    return out


def _attempt(hull, pieces, kind, nodes, Ps, checks, rate, sol: LmiSolution) -> Attempt:
    """Re-check a candidate; the pieces' shares of the dual."""
    owner = [j for _a, _b, j in checks for _V in pieces[j].vertices]  # the piece of each constraint, in order
    weights = np.bincount(owner, weights=sol.weights, minlength=len(pieces))
    spans = max(1, len(nodes) - 1)
    sides = [min(min(w), spans - 1) for wa, wb, j in checks for _V in pieces[j].vertices for w in (wa, wb)]
    by_node = np.bincount(sides, weights=np.repeat(sol.weights, 2) / 2, minlength=spans)
    cert = None
    if sol.mu > 0:
        margin = prove(hull, pieces, Ps, checks)
        if margin is not None:
            cert = Certificate(kind, tuple(nodes), tuple(Ps), rate, margin, sol.solver, len(pieces),
                               sum(len(pieces[j].vertices) for _a, _b, j in checks) + len(Ps))  # fmt: skip
    return Attempt(cert, sol.mu, weights, by_node, rate)


def prove(hull: LoopHull, pieces: list[Piece], Ps: list[np.ndarray], checks: list[Check]) -> float | None:
    """Every ``P`` node positive definite and every ``P(s) - V' P(s') V`` of ``checks`` (each vertex of the
    check's piece) positive definite, proved in ball arithmetic on the exact vertices. Returns the smallest proved
    ``lambda_min / max |P|_F`` (None: some inequality is not proved)."""
    from flint import arb, arb_mat, ctx

    old, ctx.prec = ctx.prec, PREC
    try:
        nodes = [arb_mat(P.tolist()) for P in Ps]
        if not all(verified_lambda_min(P) > 0 for P in nodes):
            return None
        top = max(float(np.linalg.norm(P)) for P in Ps)
        cache: dict = {}

        def at(w: dict[int, Fraction]):
            key = tuple(sorted(w.items()))
            if key not in cache:
                cache[key] = sum((nodes[k] * (arb(v.numerator) / v.denominator) for k, v in w.items()),
                                 arb_mat(len(Ps[0]), len(Ps[0])))  # fmt: skip
            return cache[key]

        worst = np.inf
        for wa, wb, j in checks:
            Pa, Pb = at(wa), at(wb)
            for V in hull.ball_vertices(pieces[j]):
                low = verified_lambda_min(Pa - V.transpose() * Pb * V)
                if not low > 0:
                    return None
                worst = min(worst, low / top)
        return float(worst)
    finally:
        ctx.prec = old
