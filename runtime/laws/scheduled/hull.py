"""The scheduled loop as the Lyapunov certificates see it: the velocity loop on each interval as its exact matrix
polynomial in lambda (:func:`~.lpv.loop_polynomial`), reduced to the states that matter, and hulled piece by piece
(the Bernstein coefficients of a piece of an interval are matrices whose convex hull holds the loop at every sigma
of the piece).

Reduction: with r = 0 the law sets ``e_prev = -Ci y_prev`` on every step, so after the first step the loop's state
stays on ``{e_prev = -Ci y_prev}``; a Lyapunov function on ``z = [x; delta; u_prev; y_prev]`` (``2n + m + p``
states) proves the whole loop stable. Every certificate's ``P`` is in those coordinates.

Pieces are dyadic parts ``[a, b]`` of an interval's ``lam`` in [0, 1], so their ends, and the sigmas there, are
exact rationals: the re-check takes the corners where it imposes a certificate's inequalities at their exact values.
The LMIs are solved in a scaled basis (the frozen loops' Lyapunov matrices averaged and whitened), where a
certificate's ``P`` is well conditioned; its matrices are recorded back in the loop's own coordinates.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
import scipy.linalg

from ...synthesis.lmi import congruence
from .lpv import bernstein_vertices, loop_polynomial, to_balls

_VERSIONS = itertools.count()  # a basis's identity, for the congruences kept per basis


@dataclass(frozen=True)
class Piece:
    """Part ``[a, b]`` of interval ``interval``'s lambda; ``lo``, ``hi`` its sigmas (exact); ``vertices`` the
    Bernstein vertices of the reduced loop there, float64, in the hull's scaled basis."""

    interval: int
    a: Fraction
    b: Fraction
    lo: Fraction
    hi: Fraction
    vertices: tuple[np.ndarray, ...]

    @property
    def depth(self) -> int:
        """How many halvings of its interval made it."""
        return (self.b - self.a).denominator.bit_length() - 1

    def describe(self, name: str) -> str:
        """``name in [lo, hi]`` for a message."""
        return f"{name} in [{float(self.lo):.6g}, {float(self.hi):.6g}]"


@dataclass
class Basis:
    """Where an LMI is solved: ``v = W^-1 w`` for a matrix ``W`` that starts as ``start``. A solution whose ``P``
    is too ill-conditioned for the solver to resolve a margin (a slow loop: its decrease is a small difference of
    large matrices) gives the next basis, whitened by that ``P`` (:meth:`rebase`), where the same problem is well
    conditioned."""

    W: np.ndarray
    version: int = field(default_factory=lambda: next(_VERSIONS))

    def copy(self) -> Basis:
        """The same basis, to rebase without changing this one."""
        return Basis(self.W.copy(), self.version)

    def apply(self, V: np.ndarray) -> np.ndarray:
        """A loop matrix of the outer basis in this one."""
        return np.linalg.solve(self.W, V @ self.W)

    def back(self, P: np.ndarray) -> np.ndarray:
        """A Lyapunov matrix of this basis in the outer one (``W^-T P W^-1``, symmetric)."""
        Wi = np.linalg.inv(self.W)
        out = Wi.T @ P @ Wi
        return 0.5 * (out + out.T)

    def rebase(self, Ps: list[np.ndarray]) -> None:
        """Whiten by the normalised sum of ``Ps`` (matrices of this basis)."""
        total = sum(P / np.linalg.norm(P, 2) for P in Ps)
        w, Q = np.linalg.eigh(0.5 * (total + total.T))
        self.W = self.W @ Q @ np.diag(np.maximum(w, 1e-300) ** -0.5)
        self.version = next(_VERSIONS)


@dataclass
class LoopHull:
    """The reduced velocity loop of a schedule on its intervals, exactly: float64 polynomials for the LMIs, balls
    for the re-check (formed on first use), and the pieces made from them."""

    points: tuple[Fraction, ...]
    polys: list[np.ndarray]  # per interval, (d + 1, N, N), reduced, scaled
    T: np.ndarray  # scaled basis: z = T w
    _balls_of: Callable[[int], np.ndarray]  # interval -> the reduced polynomial as balls (unscaled)
    basis: Basis = field(default_factory=lambda: Basis(np.eye(1)))  # where the LMIs are solved (set in of_polynomials)
    _balls: dict = field(default_factory=dict)  # (interval, a, b) -> Bernstein vertices as flint arb_mat
    _ball_polys: dict = field(default_factory=dict)
    _lmi: dict = field(default_factory=dict)  # (interval, a, b, basis version) -> [(vertex, congruence)]

    @classmethod
    def of(cls, s, Ci: np.ndarray) -> LoopHull:
        """The hull of the schedule ``s`` (a :class:`~gainlink.laws.scheduled.block.Schedule`) with ``Ci``."""
        raw = [reduced(loop_polynomial(s, Ci, i), s, Ci) for i in range(len(s.points) - 1)]
        balls = lambda i: reduced(loop_polynomial(s, Ci, i, balls=True), s, Ci)  # noqa: E731
        return cls.of_polynomials(s.points, raw, balls)

    @classmethod
    def of_polynomials(cls, points, polys: list[np.ndarray], balls: Callable[[int], np.ndarray] | None = None):
        """The hull of any loop given per interval by its monomial coefficients ``polys[i]`` (float64, exact as
        given unless ``balls(i)`` encloses the exact ones)."""
        T = _scaling(polys)
        Ti = np.linalg.inv(T)
        scaled = [np.array([Ti @ c @ T for c in mono]) for mono in polys]
        exact = balls or (lambda i: to_balls(polys[i]))
        return cls(tuple(Fraction(float(p)) for p in points), scaled, T, exact, Basis(np.eye(T.shape[0])))

    @property
    def N(self) -> int:
        """States of the reduced loop."""
        return self.polys[0].shape[1]

    def sigma(self, i: int, lam: Fraction) -> Fraction:
        """The sigma at ``lam`` of interval ``i`` (exact)."""
        return self.points[i] + lam * (self.points[i + 1] - self.points[i])

    def piece(self, i: int, a: Fraction, b: Fraction) -> Piece:
        """The piece ``[a, b]`` of interval ``i``."""
        verts = tuple(bernstein_vertices(self.polys[i], a, b))
        return Piece(i, a, b, self.sigma(i, a), self.sigma(i, b), verts)

    def uniform(self, per_interval: int) -> list[Piece]:
        """Every interval cut in ``per_interval`` equal pieces (a power of two), in sigma order."""
        return [self.piece(i, Fraction(j, per_interval), Fraction(j + 1, per_interval))
                for i in range(len(self.polys)) for j in range(per_interval)]  # fmt: skip

    def split(self, p: Piece) -> tuple[Piece, Piece]:
        """The two halves of a piece."""
        mid = (p.a + p.b) / 2
        return self.piece(p.interval, p.a, mid), self.piece(p.interval, mid, p.b)

    def ball_vertices(self, p: Piece) -> list:
        """The piece's Bernstein vertices as flint ``arb_mat``, in the loop's own (reduced, unscaled) coordinates,
        enclosing the exact ones of the artifact's float64 per-point matrices."""
        key = (p.interval, p.a, p.b)
        if key not in self._balls:
            from flint import arb_mat

            if p.interval not in self._ball_polys:
                self._ball_polys[p.interval] = self._balls_of(p.interval)
            verts = bernstein_vertices(self._ball_polys[p.interval], p.a, p.b)
            self._balls[key] = [arb_mat(v.tolist()) for v in verts]
        return self._balls[key]

    def lmi_vertices(self, p: Piece, basis: Basis) -> list[tuple[np.ndarray, np.ndarray]]:
        """The piece's vertices in ``basis`` with their maps ``svec(P) -> svec(V' P V)`` (kept per basis)."""
        key = (p.interval, p.a, p.b, basis.version)
        if key not in self._lmi:
            self._lmi[key] = [(V, congruence(V)) for V in (basis.apply(V) for V in p.vertices)]
        return self._lmi[key]

    def from_scaled(self, P: np.ndarray) -> np.ndarray:
        """A Lyapunov matrix of the scaled basis (the pieces' vertices') in the loop's coordinates (``z = T w``)."""
        Ti = np.linalg.inv(self.T)
        out = Ti.T @ P @ Ti
        return 0.5 * (out + out.T)


def reduced(mono: np.ndarray, s, Ci: np.ndarray) -> np.ndarray:
    """The loop's coefficients on ``z = [x; delta; u_prev; y_prev]``, ``e_prev = -Ci y_prev`` (module docstring):
    ``R A E`` with ``E`` putting ``e_prev`` back and ``R`` dropping it (float64 or balls, as ``mono``)."""
    n, m = s.design["Bd"].shape[1:]
    p, q = s.design["Cd"].shape[1], Ci.shape[0]
    r = 2 * n + m + p
    E = np.zeros((r + q, r))
    E[:r, :r] = np.eye(r)
    E[r:, 2 * n + m :] = -Ci
    R = np.eye(r, r + q)
    if mono.dtype == object:
        E, R = E.astype(object), R.astype(object)
    return np.array([R @ c @ E for c in mono])


def _scaling(polys: list[np.ndarray]) -> np.ndarray:
    """``T`` whitening the frozen loops' discrete Lyapunov matrices (``A' X A - X = -I``) at the points and the
    middles of the intervals, each normalised, summed: a basis where one ``P`` fits the whole envelope roughly."""
    total = 0.0
    for mono in polys:
        for lam in (0.0, 0.5, 1.0):
            A = sum(lam**k * c for k, c in enumerate(mono))
            X = scipy.linalg.solve_discrete_lyapunov(A.T, np.eye(A.shape[0]))
            total = total + X / np.linalg.norm(X, 2)
    w, Q = np.linalg.eigh(0.5 * (total + total.T))
    return Q @ np.diag(w**-0.5)
