"""The worst-case peak gain (WCPG) of a stable discrete system, with a rigorous upper bound.

For ``x+ = A x + B w``, ``s = C x + D w`` started at rest, ``|s_i(k)| <= sum_j W_ij max_k |w_j(k)|`` with
``W = |D| + sum_{k>=0} |C A^k B|`` (entrywise), and the bound is reached by some input of that size: it is the
tightest bound on a signal of a linear recursion driven by bounded inputs. Following Volkova, Hilaire and Lauter
("Reliable evaluation of the worst-case peak gain matrix in multiple precision", ARITH 2015):

- a **verified decomposition** of ``A`` bounds ``|C A^k B|`` for all k at once. Preferably its eigendecomposition
  ``A = V diag(l) V^-1``, enclosed in ball arithmetic (python-flint, Rump's method): then
  ``|C A^k B| <= sum_l |R_l| rho_l^k`` with ``R_l = (C v_l)(w_l B)`` and ``rho_l >= |l_l|``. When the eigenvalues
  cannot be isolated or the basis is ill-conditioned, a **Lyapunov matrix** ``P`` with ``A' P A <= gamma^2 P``
  (checked positive semidefinite in ball arithmetic) gives ``|C_i A^k B_j| <= |C_i| |B_j| kappa gamma^k``,
  ``kappa = sqrt(lambda_max(P) / lambda_min(P))``.
- the **tail** ``sum_{k>=N} |C A^k B|`` is then at most ``sum_l |R_l| rho_l^N / (1 - rho_l)`` (or
  ``|C_i| |B_j| kappa gamma^N / (1 - gamma)``); N grows until the tail is below ``rel_tol`` of the sum.
- the **head** ``sum_{k<N} |C A^k B|`` is computed in float64 (``X_k = A X_{k-1}``) with an error budget: the
  rounding of each product is at most ``gamma_n |A| |X_{k-1}|`` (Higham, Thm 3.5, any summation order, with or
  without FMA), and the error it leaves in later ``X_k`` is propagated through the same decomposition (in
  eigen-coordinates, each contracting by ``rho_l``; or in the P-norm, by ``gamma``). The bounds computed in
  float64 from these are inflated by a factor ``1 + 1e-9`` to cover their own rounding.

The result is an upper bound (and a lower bound: the head minus its error) of every entry of ``W``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..errors import DesignError
from .balls import INFLATE
from .balls import upper as _up
from .balls import verified_lambda_min as _verified_lambda_min

UNIT = 2.0**-53
EIGEN_MAX_COND = 1e8  # above this basis condition number the Lyapunov certificate is used
PREC = 128  # bits of the ball arithmetic
BLOCK = 64  # steps between tail checks


@dataclass(frozen=True)
class PeakGain:
    """A WCPG matrix bounded from above and below.

    ``upper`` (p x m) bounds ``|D| + sum_k |C A^k B|``; ``lower`` is below it; ``terms`` head terms were summed,
    leaving ``tail``; ``head_error`` bounds the float64 rounding of the head; ``method`` is the certificate
    (``eigen`` or ``lyapunov``); ``converged`` is False when the term budget ran out before the tail fell below
    the tolerance (the bound still holds, only looser).
    """

    upper: np.ndarray
    lower: np.ndarray
    terms: int
    tail: np.ndarray
    head_error: np.ndarray
    method: str
    converged: bool


def spectral_radius(A: np.ndarray) -> float:
    """Largest eigenvalue magnitude (float64 estimate)."""
    return float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0


def wcpg(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    D: np.ndarray | None = None,
    *,
    what: str = "the system",
    rel_tol: float = 1e-7,
    max_terms: int = 200_000,
) -> PeakGain:
    """Rigorous bounds on the worst-case peak gain of ``(A, B, C, D)`` (module docstring).

    Raises
    ------
    DesignError
        ``A`` is not stable (its peak gain is unbounded) or no certificate of its stability could be verified;
        the message names ``what``.
    """
    A, B, C = (np.atleast_2d(np.asarray(x, dtype=np.float64)) for x in (A, B, C))
    D = np.zeros((C.shape[0], B.shape[1])) if D is None else np.asarray(D, dtype=np.float64)
    rho = spectral_radius(A)
    if not rho < 1.0:
        raise DesignError(f"the peak gain of {what} is unbounded: its state matrix has spectral radius {rho:.6g} >= 1")
    cert = decay_certificate(A, B, C, what=what)
    head = _Head(A, B, C, cert)
    scale_floor = np.abs(D).max(axis=1, initial=0.0)
    converged = False
    while head.k < max_terms:
        head.advance(BLOCK)
        tail = cert.tail(head.k)
        row = np.maximum(head.S.max(axis=1, initial=0.0), scale_floor)
        if np.all(tail <= rel_tol * row[:, None]) or not np.any(head.X):
            converged = True
            break
    tail = cert.tail(head.k)
    S_up = head.S / (1.0 - _gamma(head.k + 1))
    err = head.error() * INFLATE
    upper = (np.abs(D) + S_up + err + tail) * INFLATE
    lower = np.maximum(np.abs(D) + head.S * (1.0 - _gamma(head.k + 1)) - err, 0.0)
    return PeakGain(upper, lower, head.k, tail, err, cert.method, converged)


def _gamma(n: int) -> float:
    """Higham's gamma_n = n u / (1 - n u)."""
    return n * UNIT / (1.0 - n * UNIT)


class _Head:
    """The float64 head sum with its running error bound."""

    def __init__(self, A: np.ndarray, B: np.ndarray, C: np.ndarray, cert) -> None:
        self.A, self.C, self.cert = A, C, cert
        self.absA, self.absC = np.abs(A), np.abs(C)
        self.gn, self.gc = _gamma(A.shape[0]), _gamma(max(C.shape[1], 1))
        self.X = B.copy()
        self.S = np.zeros((C.shape[0], B.shape[1]))
        self.err = np.zeros_like(self.S)
        self.state = cert.error_state(B.shape[1])
        self.k = 0

    def advance(self, steps: int) -> None:
        """Add ``steps`` terms ``|C A^k B|`` and their error bounds."""
        A, C, absA, absC, cert = self.A, self.C, self.absA, self.absC, self.cert
        for _ in range(steps):
            absX = np.abs(self.X)
            self.S += np.abs(C @ self.X)
            # |fl(C X) - C X| and the propagated error of X itself
            self.err += self.gc * (absC @ absX) + cert.output_error(self.state)
            eta = self.gn * (absA @ absX)  # rounding of the next product A X
            self.state = cert.propagate(self.state, eta)
            self.X = A @ self.X
            self.k += 1

    def error(self) -> np.ndarray:
        """The head's error bound (with the summation's own rounding left to the caller)."""
        return self.err


def decay_certificate(A: np.ndarray, B: np.ndarray, C: np.ndarray, *, what: str = "the system"):
    """The verified decomposition that bounds ``|C A^k B|`` for every k: the eigendecomposition when it can be
    enclosed with a basis condition number up to :data:`EIGEN_MAX_COND`, else a Lyapunov matrix. Its
    ``tail(N)`` bounds ``sum_{k>=N} |C A^k B|``; ``method`` names it."""
    try:
        cert = _EigenCertificate.verify(A, B, C)
        if cert.condition <= EIGEN_MAX_COND:
            return cert
    except (ValueError, ZeroDivisionError):
        pass
    cert = _LyapunovCertificate.verify(A, B, C)
    if cert is None:
        raise DesignError(f"could not verify that {what} is stable (no certificate of its peak gain)")
    return cert


def _up_matrix(M) -> np.ndarray:
    return np.array([[_up(M[i, j]) for j in range(M.ncols())] for i in range(M.nrows())]).reshape(M.nrows(), M.ncols())


@dataclass(frozen=True)
class _EigenCertificate:
    """``A = V diag(l) V^-1`` enclosed in balls: ``rho`` bounds |l|, the others bound |C V|, |V^-1 B|, |V^-1|."""

    rho: np.ndarray
    absCV: np.ndarray
    absWB: np.ndarray
    absW: np.ndarray
    condition: float
    method: str = "eigen"

    @classmethod
    def verify(cls, A: np.ndarray, B: np.ndarray, C: np.ndarray) -> _EigenCertificate:
        from flint import acb_mat, ctx

        V, W, rho, absW, condition = _eigen_basis(A.shape, A.tobytes())
        old, ctx.prec = ctx.prec, PREC
        try:
            absCV = _up_matrix(acb_mat(C.tolist()) * V)
            absWB = _up_matrix(W * acb_mat(B.tolist()))
        finally:
            ctx.prec = old
        return cls(rho=rho, absCV=absCV, absWB=absWB, absW=absW, condition=condition)

    def tail(self, N: int) -> np.ndarray:
        """Bound on ``sum_{k>=N} |C A^k B|``: ``sum_l |R_l| rho_l^N / (1 - rho_l)``."""
        weight = self.rho**N / (1.0 - self.rho)
        return (self.absCV * weight[None, :]) @ self.absWB * INFLATE

    def error_state(self, m: int) -> np.ndarray:
        return np.zeros((self.rho.size, m))

    def propagate(self, xi: np.ndarray, eta: np.ndarray) -> np.ndarray:
        """Eigen-coordinates of the error: each contracts by rho_l; the new rounding enters through |V^-1|."""
        return self.rho[:, None] * xi + self.absW @ eta

    def output_error(self, xi: np.ndarray) -> np.ndarray:
        return self.absCV @ xi


@dataclass(frozen=True)
class _LyapunovCertificate:
    """``A' P A <= gamma^2 P`` with ``lambda_min(P) >= lmin``, ``lambda_max(P) <= lmax`` (verified)."""

    gamma: float
    lmin: float
    lmax: float
    normC: np.ndarray
    normB: np.ndarray
    method: str = "lyapunov"

    @classmethod
    def verify(cls, A: np.ndarray, B: np.ndarray, C: np.ndarray) -> _LyapunovCertificate | None:
        found = _lyapunov_matrix(A.shape, A.tobytes())
        if found is None:
            return None
        gamma, lmin, lmax = found
        normC = np.linalg.norm(C, axis=1) * INFLATE
        normB = np.linalg.norm(B, axis=0) * INFLATE
        return cls(gamma=gamma, lmin=lmin, lmax=lmax, normC=normC, normB=normB)

    @property
    def kappa(self) -> float:
        return math.sqrt(self.lmax / self.lmin) * INFLATE

    def tail(self, N: int) -> np.ndarray:
        """Bound on ``sum_{k>=N} |C A^k B|``: ``|C_i| |B_j| kappa gamma^N / (1 - gamma)``."""
        return np.outer(self.normC, self.normB) * (self.kappa * self.gamma**N / (1.0 - self.gamma)) * INFLATE

    def error_state(self, m: int) -> np.ndarray:
        return np.zeros(m)

    def propagate(self, e: np.ndarray, eta: np.ndarray) -> np.ndarray:
        """P-norm of each column's error: contracts by gamma; the new rounding enters with sqrt(lambda_max)."""
        return self.gamma * e + math.sqrt(self.lmax) * np.linalg.norm(eta, axis=0) * INFLATE

    def output_error(self, e: np.ndarray) -> np.ndarray:
        return np.outer(self.normC, e) / math.sqrt(self.lmin) * INFLATE


@functools.lru_cache(maxsize=16)
def _eigen_basis(shape: tuple[int, ...], data: bytes) -> tuple:
    """``(V, W, rho, |W|, condition)`` of the eigendecomposition of the float64 matrix ``A`` (given by its shape and
    bytes: the same matrix is decomposed once, however many input and output columns its peak gains are taken for)
    enclosed in balls (Rump's method); ValueError when an eigenvalue's enclosure reaches the unit circle."""
    from flint import acb_mat, ctx

    A = np.frombuffer(data, dtype=np.float64).reshape(shape)
    old, ctx.prec = ctx.prec, PREC
    try:
        E, V = acb_mat(A.tolist()).eig(right=True, algorithm="rump")
        W = V.inv()
        rho = np.array([_up(e) for e in E])
        if not np.all(rho < 1.0):
            raise ValueError("an eigenvalue enclosure reaches the unit circle")
        absV, absW = _up_matrix(V), _up_matrix(W)
    finally:
        ctx.prec = old
    return V, W, rho, absW, float(np.linalg.norm(absV, 2) * np.linalg.norm(absW, 2))


@functools.lru_cache(maxsize=16)
def _lyapunov_matrix(shape: tuple[int, ...], data: bytes) -> tuple[float, float, float] | None:
    """``(gamma, lambda_min lower bound, lambda_max upper bound)`` of a verified ``P`` with ``A' P A <= gamma^2 P``
    for the float64 matrix ``A`` (its shape and bytes), or None."""
    from flint import arb_mat, ctx

    A = np.frombuffer(data, dtype=np.float64).reshape(shape)
    rho = spectral_radius(A)
    for gamma in (rho + 0.25 * (1.0 - rho), rho + 0.5 * (1.0 - rho), rho + 0.75 * (1.0 - rho)):
        P = scipy.linalg.solve_discrete_lyapunov((A / gamma).T, np.eye(A.shape[0]))
        P = 0.5 * (P + P.T)
        old, ctx.prec = ctx.prec, PREC
        try:
            Pa, Aa = arb_mat(P.tolist()), arb_mat(A.tolist())
            lmin = _verified_lambda_min(Pa)
            dissipation = _verified_lambda_min(Pa * (gamma * gamma) - Aa.transpose() * Pa * Aa)
            lmax = float(np.linalg.norm(P, "fro")) * INFLATE  # P is exact: its Frobenius norm bounds lambda_max
        finally:
            ctx.prec = old
        if lmin > 0.0 and dissipation >= 0.0:
            return gamma, lmin, lmax
    return None


@dataclass(frozen=True)
class BallPeak:
    """The peak bound of a system formed in balls (:func:`wcpg_ball`): ``upper`` (p x m) the peak gain of the
    float64 system nearest the balls, per input column; ``formed`` (p) what the entries' rounding can add for
    inputs ``|w_j| <= 1`` on every column; ``gain`` the float64 system's :class:`PeakGain` (its ``method`` and
    ``terms``)."""

    upper: np.ndarray
    formed: np.ndarray
    gain: PeakGain

    @property
    def total(self) -> np.ndarray:
        """Every output's bound for inputs ``|w_j| <= 1``."""
        return (self.upper.sum(axis=1) + self.formed) * INFLATE


def wcpg_ball(A, B, C, D=None, *, what: str = "the system") -> BallPeak:
    """The peak gain of ``(A, B, C, D)`` given as balls (numpy object arrays of python-flint ``arb``,
    :mod:`gainlink.proof.ball`; float arrays are taken as exact), with what their rounding to float64 can add.

    The peak gain is taken of the float64 matrices ``Â, B̂, Ĉ, D̂`` nearest the balls; the rest (at most
    ``Ā, B̄, C̄, D̄`` entrywise) is an injection ``ε = (A - Â) x + (B - B̂) w`` into the state and a term
    ``(C - Ĉ) x + (D - D̂) w`` on the output. With ``G`` the peak gain of ``(Â, [B̂ I], [Ĉ; I])`` (taken apart
    from the main one, ``G_ow``), the state's peak ``s`` obeys ``s <= G_xw 1 + G_xI (B̄ 1 + Ā s)``; when
    ``μ = max row sum of G_xI Ā < 1`` that gives ``|s|_inf <= |v|_inf / (1 - μ)``, ``v = G_xw 1 + G_xI B̄ 1``,
    hence ``s``, and every output is at most ``G_ow 1 + G_oI (B̄ 1 + Ā s) + C̄ s + D̄ 1`` (a small-gain argument,
    valid over every finite horizon).

    Raises
    ------
    DesignError
        ``Â`` is not stable, or the entries' rounding is not small against the loop's peak gain (``μ >= 1``).
    """
    from ..proof.ball import split

    Ah, Ab = split(A)
    Bh, Bb = split(B)
    Ch, Cb = split(C)
    n, mw, p = Ah.shape[0], Bh.shape[1], Ch.shape[0]
    Dh, Db = (np.zeros((p, mw)), np.zeros((p, mw))) if D is None else split(D)
    g = wcpg(Ah, Bh, Ch, Dh, what=what)
    if not (Ab.any() or Cb.any() or Bb.any()):  # float64 exactly
        return BallPeak(upper=g.upper, formed=Db.sum(axis=1) * INFLATE, gain=g)
    # the gains from an injection into the state, and the state's own: only for the entries' rounding (a separate
    # peak gain, so that its identity columns leave the main one's convergence as it was; the decomposition of A is
    # verified once for both)
    if not (Ab.any() or Cb.any()):  # the state's own peak is not needed
        G_oI = wcpg(Ah, np.eye(n), Ch, what=what).upper
        return BallPeak(upper=g.upper, formed=(G_oI @ Bb.sum(axis=1) + Db.sum(axis=1)) * INFLATE, gain=g)
    aux = wcpg(Ah, np.hstack([Bh, np.eye(n)]), np.vstack([Ch, np.eye(n)]), what=what).upper
    G_oI, G_xw, G_xI = aux[:p, mw:], aux[p:, :mw], aux[p:, mw:]
    M = (G_xI @ Ab) * INFLATE
    mu = float(M.sum(axis=1).max(initial=0.0)) * INFLATE
    if not mu < 1.0:
        raise DesignError(
            f"the rounding of the matrices of {what} is not small against its peak gain (small-gain factor "
            f"{mu:.3g} >= 1): its bound cannot be certified"
        )
    v = (G_xw.sum(axis=1) + G_xI @ Bb.sum(axis=1)) * INFLATE
    s = (v + M.sum(axis=1) * (float(v.max(initial=0.0)) / (1.0 - mu))) * INFLATE
    injection = (Bb.sum(axis=1) + Ab @ s) * INFLATE
    formed = (G_oI @ injection + Cb @ s + Db.sum(axis=1)) * INFLATE
    return BallPeak(upper=g.upper, formed=formed, gain=g)
