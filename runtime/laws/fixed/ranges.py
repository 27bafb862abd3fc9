"""Range bounds of every variable of the fixed-point law, for any inputs within the declared ranges and any
history (docs/design.md, fixed point: no overflow, for any compensator).

- **Estimate.** The observer is fed the saturated command, so ``xh+ = F xh + G du + Ly dy + rho_x`` with ``du``
  within the limits, ``dy`` within the sample ranges and ``|rho_x|`` at most the estimate's rounding: the WCPG of
  ``(F, [G Ly I])`` bounds ``xh`` whether or not the compensator is stable. Each input is its interval's centre
  plus a deviation of at most the half-width, so an off-centre operating point costs only the centre's own
  response. The same recursion with output ``c = Kx xh + Ky dy`` bounds the command's feedback part.
- **Integrator, clamp** (needs ``Kz`` of full column rank, left inverse ``P``, exact rationals): ``z`` only moves
  on steps where no input saturates, where ``Kz z = v - u_op - c - rho_v`` lies within the limits, so
  ``|z| <= |P| (room + |c| + h_v)``, plus one increment.
- **Integrator, back-calculation**: with ``v = u_op + c + Kz z + rho_v`` and ``uv = clamp(v)``,
  ``z+ = (I - Kaw Kz) z + Kaw (uv - u_op - c - rho_v) + Tr r + Ty y + rho_z`` on every step, saturated or not;
  with ``Phi = I - Kaw Kz`` (``(1 - aw_gain) I`` before quantisation) and ``rho(|Phi|) < 1`` (checked exactly:
  ``(I - |Phi|)^-1 >= 0``), ``|z| <= (I - |Phi|)^-1 (b + |z0|)``.
- **Command**: ``|v| <= |u_op| + |c| + |Kz| |z| + h_v``; ``|uv - v| <= room + |c| + |Kz| |z| + h_v``.

All with the coefficients, operating point and limits the integers mean, and the rounding of each output
(``h``, half a unit in its last place) as an input: a bound computed here is a bound of the integer law.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ...errors import DesignError
from ...proof.ball import balls, mid, precise
from ...proof.derived_law import DerivedLaw
from ...synthesis.wcpg import PeakGain, wcpg_ball


@dataclass(frozen=True)
class InputRanges:
    """Intervals ``(lo, hi)`` of the law's inputs, in real units: ``dy`` and ``y`` (p), ``r`` (q), ``du`` (m)."""

    dy: tuple[np.ndarray, np.ndarray]
    y: tuple[np.ndarray, np.ndarray]
    r: tuple[np.ndarray, np.ndarray]
    du: tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class Rounding:
    """Half a unit in the last place of each rounding point (0 where there is no rounding): the samples ``y``
    (p) and references ``r`` (q), the unsaturated command ``v`` and the command ``u`` (m), ``z`` (q), ``xh`` (n);
    and ``c`` (m), how far the float the C returns can be from the command word's value (``(float)U``: 0 when
    every word of the command's range is a float32)."""

    y: np.ndarray
    r: np.ndarray
    v: np.ndarray
    u: np.ndarray
    z: np.ndarray
    x: np.ndarray
    c: np.ndarray


@dataclass(frozen=True)
class RangeBounds:
    """Bounds of ``|xh|`` (n), ``|c|`` (m, the feedback ``Kx xh + Ky dy``), ``|z|`` (q), ``|v|`` and ``|uv - v|``
    (m), and the estimate's peak gain with the scaled input columns it was computed for."""

    xh: np.ndarray
    c: np.ndarray
    z: np.ndarray
    v: np.ndarray
    w: np.ndarray
    gain: PeakGain
    columns: np.ndarray
    feedthrough: np.ndarray


def centre_half(interval: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The centre and half-width of the interval ``(lo, hi)`` (floats or balls), as balls."""
    lo, hi = (balls(x) for x in interval)
    return (lo + hi) * 0.5, (hi - lo) * 0.5


@precise
def estimate_columns(law: DerivedLaw, ranges: InputRanges, h: Rounding) -> np.ndarray:
    """The input columns of the estimate recursion ``xh+ = F xh + G du + Ly dy + rho_x`` with unit-bounded inputs
    (balls, n x (1 + m + p + n + 1)): ``[centre, du, dy, rounding, xh0]``, each deviation scaled by its
    half-width."""
    cu, hu = centre_half(ranges.du)
    cy, hy = centre_half(ranges.dy)
    G, Ly = balls(law.G), balls(law.Ly)
    return np.hstack([(G @ cu + Ly @ cy)[:, None], G * hu[None, :], Ly * hy[None, :], np.diag(h.x), law.xh0[:, None]])


@precise
def estimate_outputs(
    law: DerivedLaw, ranges: InputRanges, X: np.ndarray, U: np.ndarray, Y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(C, D)`` of the signal ``X xh + U du + Y dy`` (each row one output) over :func:`estimate_columns`."""
    cu, hu = centre_half(ranges.du)
    cy, hy = centre_half(ranges.dy)
    U, Y = balls(U), balls(Y)
    m, p = law.m, law.p
    D = np.zeros((X.shape[0], 1 + m + p + law.n + 1), dtype=object)
    D[:, 0] = U @ cu + Y @ cy
    D[:, 1 : 1 + m] = U * hu[None, :]
    D[:, 1 + m : 1 + m + p] = Y * hy[None, :]
    return X, D


def estimate_system(law: DerivedLaw, ranges: InputRanges, h: Rounding) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(B, C, D)`` of the estimate recursion (:func:`estimate_columns`) with outputs ``[xh; c]``,
    ``c = Kx xh + Ky dy`` the command's feedback part."""
    n, m, p = law.n, law.m, law.p
    X = np.vstack([np.eye(n), law.Kx])
    C, D = estimate_outputs(law, ranges, X, np.zeros((n + m, m)), np.vstack([np.zeros((n, p)), law.Ky]))
    return estimate_columns(law, ranges, h), C, D


def range_bounds(law: DerivedLaw, ranges: InputRanges, h: Rounding) -> RangeBounds:
    """Every variable's bound (module docstring).

    Raises
    ------
    DesignError
        ``F`` is unstable (the estimate is unbounded) or the integrator cannot be bounded.
    """
    B, C, D = estimate_system(law, ranges, h)
    peak = wcpg_ball(law.F, B, C, D, what="the estimate (the observer's error dynamics F)")
    total = peak.total
    xh, c = total[: law.n], total[law.n :]
    room = np.maximum(law.hi - law.u_op, law.u_op - law.lo)
    z = _integrator_bound(law, ranges, h, room + c + h.v)
    kz_z = np.abs(law.Kz) @ z
    v = (np.abs(law.u_op) + c + kz_z + h.v) * (1 + 1e-12)
    w = (room + c + kz_z + h.v) * (1 + 1e-12)
    return RangeBounds(xh=xh, c=c, z=z, v=v, w=w, gain=peak.gain, columns=mid(B), feedthrough=mid(D))


def _increment_bound(law: DerivedLaw, ranges: InputRanges) -> np.ndarray:
    """``max |Tr r + Ty y|`` over the ranges (interval arithmetic, exact for a sum of independent terms)."""
    r_lo, r_hi = ranges.r
    y_lo, y_hi = ranges.y
    lo = np.minimum(law.Tr * r_lo, law.Tr * r_hi) + np.minimum(law.Ty * y_lo, law.Ty * y_hi).sum(axis=1)
    hi = np.maximum(law.Tr * r_lo, law.Tr * r_hi) + np.maximum(law.Ty * y_lo, law.Ty * y_hi).sum(axis=1)
    return np.maximum(np.abs(lo), np.abs(hi)) * (1 + 1e-12)


def _integrator_bound(law: DerivedLaw, ranges: InputRanges, h: Rounding, reach: np.ndarray) -> np.ndarray:
    """``|z|`` bound for clamp or back-calculation; ``reach`` bounds ``|uv - u_op - c - rho_v|`` per input."""
    if law.q == 0:
        return np.zeros(0)
    step = _increment_bound(law, ranges) + h.z
    z0 = np.abs(law.z0)
    if law.anti_windup == "clamp":
        P = _left_inverse(law.Kz)
        return np.maximum(z0, _matvec_up(_abs(P), reach) + step) * (1 + 1e-12)
    if law.anti_windup == "backcalc":
        Phi = _exact(np.eye(law.q)) - _exact(law.Kaw) * _exact(law.Kz)
        inv = _nonnegative_inverse(_exact(np.eye(law.q)) - _abs(Phi))
        b = _matvec_up(_abs(_exact(law.Kaw)), reach) + step + z0
        return _matvec_up(inv, b) * (1 + 1e-12)
    raise DesignError(
        f'the integrator cannot be bounded with anti_windup = "{law.anti_windup}" in fixed point: use clamp or backcalc'
    )


def _exact(M: np.ndarray):
    """A float matrix as an exact rational flint matrix."""
    from flint import fmpq, fmpq_mat

    M = np.atleast_2d(M)
    return fmpq_mat(M.shape[0], M.shape[1], [fmpq(*float(x).as_integer_ratio()) for x in M.ravel()])


def _abs(M):
    from flint import fmpq_mat

    return fmpq_mat(M.nrows(), M.ncols(), [abs(M[i, j]) for i in range(M.nrows()) for j in range(M.ncols())])


def _matvec_up(M, x: np.ndarray) -> np.ndarray:
    """``M x`` for a non-negative rational ``M`` and float ``x``, rounded up."""
    out = []
    for i in range(M.nrows()):
        s = sum(
            (Fraction(int(M[i, j].p), int(M[i, j].q)) * Fraction(float(x[j])) for j in range(M.ncols())), Fraction(0)
        )
        f = float(s)
        out.append(f if Fraction(f) >= s else float(np.nextafter(f, np.inf)))
    return np.array(out)


def _left_inverse(Kz: np.ndarray):
    """``(Kz' Kz)^-1 Kz'`` in exact rationals; DesignError when ``Kz`` lacks full column rank."""
    K = _exact(Kz)
    try:
        return (K.transpose() * K).inv() * K.transpose()
    except ZeroDivisionError:
        raise DesignError(
            'anti_windup = "clamp" in fixed point needs Ki of full column rank (the integrator is bounded through '
            "Ki z on the steps it moves)"
        ) from None


def _nonnegative_inverse(M):
    """``M^-1`` for ``M = I - |Phi|``; DesignError unless it exists and is entrywise >= 0 (i.e. rho(|Phi|) < 1)."""
    try:
        inv = M.inv()
    except ZeroDivisionError:
        inv = None
    if inv is None or any(inv[i, j] < 0 for i in range(inv.nrows()) for j in range(inv.ncols())):
        raise DesignError(
            "the back-calculation integrator does not contract in fixed point (rho(|I - Kaw Ki|) >= 1: Ki lacks full "
            'column rank, or the quantised Kaw Ki is too far from aw_gain I): use anti_windup = "clamp" or q31'
        )
    return inv
