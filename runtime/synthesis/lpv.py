"""The scheduled loop as matrices: frozen at one sigma (positional form, the design there) and as the velocity
form the C runs (the system whose stability under a moving sigma is the question), plus the polynomial-in-lambda
structure of the latter on each interval between points.

Plant between points: the points' sampled plants ``(Ad, Bd, Cd, Dd)`` interpolated linearly, the same
interpolation as the law's coefficients. Outputs are ``y = Cd x + Dd u`` with the same step's command (as
:func:`~gainlink.synthesis.loop.closed_loop_matrix`); ``Ky Dd = 0`` always holds (the current form has ``Dd = 0``,
the predictor ``Ky = 0``), so there is no algebraic loop. References are zero: these are the loops' own dynamics.
"""

from __future__ import annotations

import numpy as np

#: Degree in lambda of the velocity loop's matrix on one interval: products of at most three interpolated
#: matrices (``Bd Ky Cd``, ``G Ky Cd``, ``Ly Dd Kx``), fitted with one degree to spare and verified.
LAMBDA_DEGREE = 4


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
    :func:`frozen_loop` plus ``m + p`` at z = 0.
    """
    Ad, Bd, Cd, Dd = plant
    n, m = Bd.shape
    p, q = Cd.shape[0], Ci.shape[0]
    N = 2 * n + m + p + q
    cols = np.cumsum([0, n, n, m, p, q])
    X, D, Up, Yp, Ep = (np.eye(N)[cols[k] : cols[k + 1]] for k in range(5))  # selectors of the state's parts
    du = -c["Kx"] @ D - c["Ky"] @ (Cd @ X - Yp) - c["Kz"] @ Ep  # Ky Dd = 0: the Dd u term drops
    U = Up + du
    Y = Cd @ X + Dd @ U
    dy = Y - Yp
    return np.vstack([Ad @ X + Bd @ U, c["F"] @ D + c["G"] @ du + c["Ly"] @ dy, U, Y, -Ci @ Y])


def lambda_polynomial(fn, *, degree: int = LAMBDA_DEGREE) -> np.ndarray:
    """Monomial coefficients ``c[j]`` with ``fn(lam) = sum_j lam**j c[j]`` for a matrix polynomial ``fn`` of at most
    ``degree`` (fitted at Chebyshev nodes of [0, 1], verified at three other points)."""
    nodes = 0.5 - 0.5 * np.cos(np.pi * (np.arange(degree + 1) + 0.5) / (degree + 1))
    values = np.array([fn(t) for t in nodes])
    mono = np.tensordot(np.linalg.inv(np.vander(nodes, degree + 1, increasing=True)), values, axes=1)
    for t in (0.0, 0.37, 1.0):
        want = fn(t)
        if np.linalg.norm(evaluate(mono, t) - want) > 1e-8 * max(1.0, float(np.linalg.norm(want))):
            raise ValueError("the scheduled loop is not polynomial in lambda of the expected degree")
    return mono


def evaluate(mono: np.ndarray, lam: float) -> np.ndarray:
    """``sum_j lam**j mono[j]`` (Horner)."""
    out = mono[-1].copy()
    for c in mono[-2::-1]:
        out = out * lam + c
    return out


def bernstein_vertices(fn, *, degree: int = LAMBDA_DEGREE) -> list[np.ndarray]:
    """The Bernstein coefficients of the matrix polynomial ``fn(lam)`` on ``[0, 1]``.

    ``fn(lam) = sum_k b_k(lam) V_k`` with Bernstein weights ``b_k >= 0`` summing to one, so ``fn(lam)`` lies in
    the convex hull of the ``V_k`` for every lam in [0, 1] (and ``V_0 = fn(0)``, ``V_d = fn(1)``).
    """
    from math import comb

    mono = lambda_polynomial(fn, degree=degree)
    # lam^j = sum_{k >= j} C(k, j) / C(d, j) b_k(lam)
    return [sum(comb(k, j) / comb(degree, j) * mono[j] for j in range(k + 1)) for k in range(degree + 1)]


def subdivided_vertices(fn, *, pieces: int) -> list[np.ndarray]:
    """Bernstein vertices of ``fn`` on each of ``pieces`` equal parts of [0, 1]: a tighter hull of the same curve."""
    out = []
    for j in range(pieces):
        a, b = j / pieces, (j + 1) / pieces
        out += bernstein_vertices(lambda t, a=a, b=b: fn(a + (b - a) * t))
    return out
