"""DLQR through python-control's Riccati solver (SLICOT via slycot), with the problem scaled first.

Weights that span many decades (an integrator weighted 1e11 beside states weighted 1) make the
symplectic pencil of the DARE badly scaled, and the solver then fails or refuses. The DARE is
invariant under a diagonal change of state coordinates ``x = S x'`` (``A' = S^-1 A S``,
``B' = S^-1 B``, ``Q' = S Q S``, ``K = K' S^-1``) and under a common factor on ``Q`` and ``R``, so the
solver is given the scaled problem and the gain is mapped back. A problem that is truly unsolvable
(a mode on or outside the unit circle that the weights cannot see, or that the inputs cannot move)
is named instead of reported as a bare solver failure.
"""

from __future__ import annotations

import numpy as np

from ..errors import DesignError


def solve_dlqr(
    A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray, *, states: list[str], warnings: list[str]
) -> np.ndarray:
    """The DLQR gain ``K`` (``u = -K x``) for ``(A, B, Q, R)``; DesignError naming the mode that prevents one."""
    import control

    _check_weights_see_marginal_modes(A, Q, states)
    try:
        K, _, _ = control.dlqr(A, B, Q, R)
        return np.asarray(K, float)
    except Exception as exc:  # SLICOT/SciPy report failures with assorted exception types
        first_error = (str(exc).splitlines() or [""])[0] or type(exc).__name__
    S, c = _scaling(Q, R)
    try:
        Ks, _, _ = control.dlqr(A / S[:, None] * S[None, :], B / S[:, None], (Q * S[:, None] * S[None, :]) / c, R / c)
    except Exception:  # the unscaled failure is the one to report
        raise DesignError(f"DLQR failed, also with the problem scaled: {first_error}") from None
    warnings.append(
        f"DLQR was solved with the states rescaled (weights span {_spread(Q, R):.2g}x): the unscaled "
        f"problem failed ({first_error})"
    )
    return np.asarray(Ks, float) / S[None, :]


def _scaling(Q: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, float]:
    """State scaling ``S`` that brings the diagonal of ``Q`` to one (a zero weight keeps scale 1) and the common
    factor ``c`` that brings ``R`` to unit size."""
    d = np.abs(np.diag(Q))
    S = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 1.0)
    return S, float(np.max(np.abs(np.diag(R))))


def _spread(Q: np.ndarray, R: np.ndarray) -> float:
    w = np.concatenate([np.abs(np.diag(Q)), np.abs(np.diag(R))])
    w = w[w > 0]
    return float(w.max() / w.min())


def _check_weights_see_marginal_modes(A: np.ndarray, Q: np.ndarray, states: list[str]) -> None:
    """A mode on the unit circle that ``Q`` cannot see has no stabilising DARE solution: name it (PBH test)."""
    n = A.shape[0]
    w, V = np.linalg.eig(A)
    Qh = _psd_sqrt(Q)
    for k in range(n):
        if abs(abs(w[k]) - 1.0) > 1e-9:
            continue
        if np.linalg.matrix_rank(np.vstack([A - w[k] * np.eye(n), Qh]), tol=1e-9 * max(1.0, np.linalg.norm(A))) < n:
            main = states[int(np.argmax(np.abs(V[:, k])))]
            raise DesignError(
                f"DLQR has no stabilising solution: the mode at z = {_fmt(w[k])} (mostly "
                f"{main}) lies on the unit circle and the weights do not see it: give it a weight in Q"
            )


def _psd_sqrt(Q: np.ndarray) -> np.ndarray:
    e, U = np.linalg.eigh((Q + Q.T) / 2)
    return (U * np.sqrt(np.clip(e, 0.0, None))) @ U.T


def _fmt(z: complex) -> str:
    return f"{z.real:.6g}" if abs(z.imag) < 1e-12 else f"{z.real:.6g}{z.imag:+.6g}j"
