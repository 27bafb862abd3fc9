"""The scheduled loop as matrices: frozen at one sigma (positional form, the design there) and as the velocity
form the C runs (the system whose stability under a moving sigma is the question), plus the polynomial-in-lambda
structure of the latter on each interval between points.

On an interval every coefficient the law runs and every plant matrix is affine in lambda, ``X(lam) = X_i + lam
(X_i+1 - X_i)``, so the velocity loop is a matrix polynomial in lambda of degree at most three (``Bd Ky Cd``, ``G Ky
Cd``, ``Ly Dd Kx``). :func:`loop_polynomial` forms it by products of those affine matrices, coefficient by
coefficient: in float64 for the LMIs, or in ball arithmetic (python-flint ``arb``, :data:`PREC` bits) for the
re-check of a certificate, where it encloses the exact polynomial of the artifact's float64 per-point matrices.

Plant between points: the points' sampled plants ``(Ad, Bd, Cd, Dd)`` interpolated linearly, the same
interpolation as the law's coefficients. Outputs are ``y = Cd x + Dd u`` with the same step's command (as
:func:`~gainlink.synthesis.loop.closed_loop_matrix`); ``Ky Dd = 0`` always holds (the current form has ``Dd = 0``,
the predictor ``Ky = 0``), so there is no algebraic loop. References are zero: these are the loops' own dynamics.
"""

from __future__ import annotations

from fractions import Fraction
from math import comb

import numpy as np

#: Bits of the ball arithmetic the exact loop polynomial is formed in (products of three float64 numbers need 159).
PREC = 256


def frozen_loop(plant: tuple, c: dict, *, Ci: np.ndarray, Ts: float, break_input: int | None = None):
    """State matrix of plant + positional law with coefficients ``c`` on ``[x; xh; z]`` (r = 0); with
    ``break_input = i``, ``(A, B, C)`` of the loop broken at plant input i (the observer keeps its own command),
    as :func:`~gainlink.synthesis.loop.closed_loop_matrix` breaks it."""
    Ad, Bd, Cd, Dd = plant
    n, m = Bd.shape
    q = Ci.shape[0]
    V = np.hstack([-c["Ky"] @ Cd, -c["Kx"], -c["Kz"] / Ts])
    A0 = np.block(
        [
            [Ad, np.zeros((n, n)), np.zeros((n, q))],
            [c["Ly"] @ Cd, c["F"], np.zeros((n, q))],
            [-Ts * Ci @ Cd, np.zeros((q, n)), np.eye(q)],
        ]
    )
    B_plant = np.vstack([Bd, c["Ly"] @ Dd, -Ts * Ci @ Dd])
    B_own = np.vstack([np.zeros((n, m)), c["G"], np.zeros((q, m))])
    if break_input is None:
        return A0 + (B_plant + B_own) @ V
    S = np.eye(m)
    S[break_input, break_input] = 0.0
    e = np.zeros((m, 1))
    e[break_input] = 1.0
    return A0 + B_plant @ S @ V + B_own @ V, B_plant @ e, V[break_input : break_input + 1, :]


def velocity_loop(plant: tuple, c: dict, *, Ci: np.ndarray) -> np.ndarray:
    """State matrix of plant + velocity-form law, unsaturated, on ``[x; delta; u_prev; y_prev; e_prev]``.

    ``du = -Kx delta - Ky (y - y_prev) - Kz e_prev``, ``u = u_prev + du``, ``delta+ = F delta + G du + Ly (y -
    y_prev)``, ``u_prev+ = u``, ``y_prev+ = y``, ``e_prev+ = -Ci y``. Frozen, its eigenvalues are those of
    :func:`frozen_loop` plus ``m + p`` at z = 0. The plant and the coefficients may also be affine matrix
    polynomials in lambda (:func:`loop_polynomial`): the result is then the loop's polynomial.
    """
    Ad, Bd, Cd, Dd = plant
    n, m = Bd.shape
    p, q = Cd.shape[0], Ci.shape[0]
    N = 2 * n + m + p + q
    cols = np.cumsum([0, n, n, m, p, q])
    X, D, Up, Yp, Ep = (np.eye(N)[cols[k] : cols[k + 1]] for k in range(5))  # selectors of the state's parts
    du = -(c["Kx"] @ D) - c["Ky"] @ (Cd @ X - Yp) - c["Kz"] @ Ep  # Ky Dd = 0: the Dd u term drops
    U = du + Up
    Y = Cd @ X + Dd @ U
    dy = Y - Yp
    rows = [Ad @ X + Bd @ U, c["F"] @ D + c["G"] @ du + c["Ly"] @ dy, U, Y, -(Ci @ Y)]
    return _Poly.vstack(rows) if isinstance(rows[0], _Poly) else np.vstack(rows)


class _Poly:
    """A matrix polynomial in lambda: ``c[j]`` (float64 or object arrays of flint balls) multiplies ``lam**j``.
    Supports what :func:`velocity_loop` does with its matrices: ``@``, ``+``, ``-``, stacking."""

    __array_ufunc__ = None  # numpy hands ``ndarray @ _Poly`` to :meth:`__rmatmul__`

    def __init__(self, c: np.ndarray) -> None:
        self.c = c

    @property
    def shape(self) -> tuple[int, int]:
        """The matrices' shape."""
        return self.c.shape[1:]

    @staticmethod
    def of(x) -> _Poly:
        return x if isinstance(x, _Poly) else _Poly(np.asarray(x)[None])

    def __matmul__(self, other) -> _Poly:
        o = _Poly.of(other)
        out = [None] * (len(self.c) + len(o.c) - 1)
        for i, a in enumerate(self.c):
            for j, b in enumerate(o.c):
                out[i + j] = a @ b if out[i + j] is None else out[i + j] + a @ b
        return _Poly(np.array(out))

    def __rmatmul__(self, other) -> _Poly:
        return _Poly.of(other) @ self

    def __add__(self, other) -> _Poly:
        o = _Poly.of(other)
        short, long = sorted((self.c, o.c), key=len)
        out = long.copy()
        out[: len(short)] = out[: len(short)] + short
        return _Poly(out)

    def __neg__(self) -> _Poly:
        return _Poly(-self.c)

    def __sub__(self, other) -> _Poly:
        return self + (-_Poly.of(other))

    @staticmethod
    def vstack(parts: list[_Poly]) -> _Poly:
        d = max(len(p.c) for p in parts)
        padded = [np.concatenate([p.c, 0 * p.c[:1].repeat(d - len(p.c), axis=0)]) for p in parts]
        return _Poly(np.concatenate(padded, axis=1))


def loop_polynomial(s, Ci: np.ndarray, i: int, *, balls: bool = False) -> np.ndarray:
    """Monomial coefficients ``(d + 1, N, N)`` of the velocity loop on interval ``i`` of the schedule ``s`` (a
    :class:`~gainlink.laws.scheduled.block.Schedule`), ``lam = (sigma - points[i]) / (points[i+1] - points[i])``:
    formed exactly from the affine coefficients, in float64 or (``balls``) as an object array of flint ``arb``
    enclosing the exact polynomial. Coefficients that are exactly zero at the top are dropped (d <= 3)."""
    conv = to_balls if balls else (lambda a: np.asarray(a, dtype=float))

    def affine(stack: np.ndarray) -> _Poly:
        lo, hi = conv(stack[i]), conv(stack[i + 1])
        return _Poly(np.array([lo, hi - lo]))

    with _precision(balls):
        plant = tuple(affine(s.design[k]) for k in ("Ad", "Bd", "Cd", "Dd"))
        coef = {k: affine(v) for k, v in s.coef.items()}
        mono = velocity_loop(plant, coef, Ci=conv(Ci)).c
    while len(mono) > 1 and all(v == 0 for v in np.ravel(mono[-1])):
        mono = mono[:-1]
    return mono


def bernstein_weights(degree: int, a: Fraction, b: Fraction) -> list[list[Fraction]]:
    """``W`` with ``V_k = sum_j W[k][j] c_j``: the Bernstein coefficients on ``[a, b]`` (of [0, 1]) of the
    polynomial with monomial coefficients ``c_j``. Exact (``a``, ``b`` rational): substitute ``lam = a + (b - a) t``,
    then ``t^i = sum_{k >= i} C(k, i) / C(d, i) b_k(t)``."""
    w = b - a
    shift = [[Fraction(comb(j, i)) * a ** (j - i) * w**i if j >= i else Fraction(0) for j in range(degree + 1)]
             for i in range(degree + 1)]  # fmt: skip
    to_bernstein = [[Fraction(comb(k, i), comb(degree, i)) if i <= k else Fraction(0) for i in range(degree + 1)]
                    for k in range(degree + 1)]  # fmt: skip
    return [[sum(to_bernstein[k][i] * shift[i][j] for i in range(degree + 1)) for j in range(degree + 1)]
            for k in range(degree + 1)]  # fmt: skip


def bernstein_vertices(mono: np.ndarray, a: Fraction = Fraction(0), b: Fraction = Fraction(1)) -> list[np.ndarray]:
    """The Bernstein coefficients on ``[a, b]`` of the matrix polynomial with monomial coefficients ``mono``.

    ``p(lam) = sum_k b_k(t) V_k`` with ``lam = a + (b - a) t`` and Bernstein weights ``b_k >= 0`` summing to one, so
    ``p(lam)`` lies in the convex hull of the ``V_k`` for every lam in [a, b] (and ``V_0 = p(a)``, ``V_d = p(b)``).
    Float64 for a float ``mono``; balls for an object array of ``arb`` (the weights then enter as exact ratios).
    """
    W = bernstein_weights(len(mono) - 1, Fraction(a), Fraction(b))
    if mono.dtype == object:
        with _precision(True):
            from flint import arb

            return [sum(arb(f.numerator) / f.denominator * c for f, c in zip(row, mono)) for row in W]
    return [sum(float(f) * c for f, c in zip(row, mono)) for row in W]


def to_balls(a) -> np.ndarray:
    """A float64 array as an object array of flint ``arb`` (exact)."""
    from flint import arb

    arr = np.asarray(a, dtype=float)
    return np.array([arb(float(v)) for v in arr.ravel()], dtype=object).reshape(arr.shape)


class _precision:
    """Context: flint's working precision at :data:`PREC` bits (``on``), restored after."""

    def __init__(self, on: bool) -> None:
        self.on = on

    def __enter__(self) -> None:
        if self.on:
            from flint import ctx

            self.old, ctx.prec = ctx.prec, max(ctx.prec, PREC)

    def __exit__(self, *exc) -> None:
        if self.on:
            from flint import ctx

            ctx.prec = self.old
