"""Structural analysis of a plant: modes and the PBH test, controllability, observability, zeros, scaling.

The PBH test is run per distinct eigenvalue so that a failure names the mode, which is what a
designer needs to fix the plant or the sensor set. Rank decisions use singular values relative
to the matrices' size, never exact zero tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RANK_RTOL = 1e-9
BADLY_SCALED_RATIO = 1e4


@dataclass(frozen=True)
class Mode:
    """One distinct eigenvalue of A with its PBH verdicts."""

    eigenvalue: complex
    stable: bool
    controllable: bool
    observable: bool


def complex_pairs(values) -> list[list[float]]:
    """Complex numbers as ``[re, im]`` lists of floats (for JSON)."""
    return [[float(np.real(v)) + 0.0, float(np.imag(v)) + 0.0] for v in values]


def is_stable(eigenvalue: complex, *, discrete: bool, margin: float = 1e-9) -> bool:
    """True when the eigenvalue is strictly inside the stability region."""
    if discrete:
        return abs(eigenvalue) < 1.0 - margin
    return eigenvalue.real < -margin


def distinct_eigenvalues(A: np.ndarray, tol: float = 1e-7) -> list[complex]:
    """Eigenvalues of A with repeats (within ``tol`` relative) merged."""
    out: list[complex] = []
    scale = max(1.0, float(np.max(np.abs(A)))) if A.size else 1.0
    for lam in sorted(np.linalg.eigvals(A), key=lambda z: (z.real, z.imag)):
        if not any(abs(lam - o) <= tol * scale for o in out):
            out.append(complex(lam))
    return out


def _rank_deficient(M: np.ndarray, n: int) -> bool:
    s = np.linalg.svd(M, compute_uv=False)
    return s.size < n or s[n - 1] <= RANK_RTOL * max(1.0, s[0])


def pbh_controllable(A: np.ndarray, B: np.ndarray, lam: complex) -> bool:
    """PBH: the mode ``lam`` is controllable iff rank [lam I - A, B] = n."""
    n = A.shape[0]
    return not _rank_deficient(np.hstack([lam * np.eye(n) - A, B]), n)


def pbh_observable(A: np.ndarray, C: np.ndarray, lam: complex) -> bool:
    """PBH: the mode ``lam`` is observable iff rank [lam I - A; C] = n."""
    n = A.shape[0]
    return not _rank_deficient(np.vstack([lam * np.eye(n) - A, C]), n)


def modes(A: np.ndarray, B: np.ndarray, C: np.ndarray, *, discrete: bool) -> list[Mode]:
    """PBH verdicts for every distinct eigenvalue of A."""
    return [
        Mode(
            eigenvalue=lam,
            stable=is_stable(lam, discrete=discrete),
            controllable=pbh_controllable(A, B, lam),
            observable=pbh_observable(A, C, lam),
        )
        for lam in distinct_eigenvalues(A)
    ]


def uncontrollable_unstable(A: np.ndarray, B: np.ndarray, *, discrete: bool) -> list[complex]:
    """The modes that make (A, B) not stabilizable (empty when stabilizable)."""
    return [
        lam
        for lam in distinct_eigenvalues(A)
        if not is_stable(lam, discrete=discrete) and not pbh_controllable(A, B, lam)
    ]


def unobservable_unstable(A: np.ndarray, C: np.ndarray, *, discrete: bool) -> list[complex]:
    """The modes that make (A, C) not detectable (empty when detectable)."""
    return [
        lam
        for lam in distinct_eigenvalues(A)
        if not is_stable(lam, discrete=discrete) and not pbh_observable(A, C, lam)
    ]


def rank_and_cond(M: np.ndarray, n: int) -> tuple[int, float]:
    """Numerical rank of M and the condition number of its first n singular values."""
    s = np.linalg.svd(M, compute_uv=False)
    rank = int(np.sum(s > RANK_RTOL * max(1.0, s[0])))
    cond = float(s[0] / s[n - 1]) if s.size >= n and s[n - 1] > 0 else float("inf")
    return rank, cond


def transmission_zeros(A, B, C, D) -> np.ndarray:
    """Invariant (transmission) zeros of (A, B, C, D), from the generalized eigenvalues of Rosenbrock's pencil."""
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    if p != m:
        # Non-square: the normal rank drops only at zeros common to every square sub-pencil,
        # which SLICOT's AB08ND computes through python-control.
        import control

        return np.asarray(control.ss(A, B, C, D).zeros())
    import scipy.linalg  # here, not at the top: the HIL bridge imports this module for complex_pairs only

    pencil_a = np.block([[A, B], [C, D]])
    pencil_b = np.block([[np.eye(n), np.zeros((n, m))], [np.zeros((p, n)), np.zeros((p, m))]])
    with np.errstate(all="ignore"):
        z = scipy.linalg.eigvals(pencil_a, pencil_b)
    return z[np.isfinite(z) & (np.abs(z) < 1e10)]


def pole_frequency(pole: complex, *, discrete: bool, Ts: float) -> float:
    """Natural frequency (rad/s) of a pole; discrete poles through s = ln(z)/Ts."""
    if discrete:
        return float(abs(np.log(max(abs(pole), 1e-12)) + 1j * np.angle(pole)) / Ts)
    return float(abs(pole))


def state_scaling(A: np.ndarray, B: np.ndarray, C: np.ndarray, names) -> tuple[float, list[str]]:
    """Spread of the balancing scale factors of the system matrix and the states at its extremes."""
    import scipy.linalg

    n = A.shape[0]
    big = np.zeros((n + 1, n + 1))
    big[:n, :n] = A
    big[:n, n] = np.max(np.abs(B), axis=1)
    big[n, :n] = np.max(np.abs(C), axis=0)
    _, (scale, _) = scipy.linalg.matrix_balance(big, permute=False, separate=True)
    s = scale[:n]
    ratio = float(np.max(s) / np.min(s))
    if ratio < BADLY_SCALED_RATIO:
        return ratio, []
    lo, hi = int(np.argmin(s)), int(np.argmax(s))
    return ratio, [names[lo], names[hi]]


def format_eigenvalue(z: complex) -> str:
    z = complex(z)
    if abs(z.imag) < 1e-12:
        return f"{z.real:.4g}"
    return f"{z.real:.4g}{z.imag:+.4g}j"
