"""Ball arithmetic (python-flint's ``arb``/``acb``) turned into float64 bounds that hold rigorously: the upper end
of a ball's absolute value, and a lower bound of the smallest eigenvalue of a symmetric ball matrix (Rump's test).
The worst-case peak gain (:mod:`.wcpg`) and the scheduled law's Lyapunov certificates
(:mod:`gainlink.laws.scheduled.lyapunov`) prove their matrices positive definite with these."""

from __future__ import annotations

import math

import numpy as np

#: Covers the float64 rounding of a bound's own arithmetic (a handful of operations on positive numbers).
INFLATE = 1.0 + 1e-9


def upper(x) -> float:
    """A float64 at or above the upper end of the absolute value of a flint ball (arb or acb)."""
    from flint import acb

    u = (abs(x) if isinstance(x, acb) else x).abs_upper()
    man, exp = u.man_exp()
    man = int(man)
    value = math.ldexp(float(man), int(exp))
    return float(np.nextafter(value, np.inf)) if man.bit_length() > 53 else value


def verified_lambda_min(M) -> float:
    """A lower bound of the smallest eigenvalue of the symmetric ball matrix ``M`` (-inf when not positive).

    Rump's test: with ``delta`` half the approximate smallest eigenvalue and ``L`` the float Cholesky factor of
    ``mid(M) - delta I``, every matrix in ``M`` is ``L L' + delta I + E`` with ``|E|_2 <= |E|_F``; if that is below
    ``delta``, the smallest eigenvalue is at least ``delta - |E|_F``.
    """
    from flint import arb_mat

    n = M.nrows()
    mid = np.array([[float(x) for x in row] for row in M.mid().tolist()])
    mid = 0.5 * (mid + mid.T)
    approx = float(np.linalg.eigvalsh(mid).min())
    if not approx > 0.0:
        return -math.inf
    delta = 0.5 * approx
    try:
        L = np.linalg.cholesky(mid - delta * np.eye(n))
    except np.linalg.LinAlgError:
        return -math.inf
    La = arb_mat(L.tolist())
    E = M - La * La.transpose() - arb_mat(np.eye(n).tolist()) * delta
    frob = math.sqrt(upper((E * E.transpose()).trace())) * INFLATE  # |E|_F^2 = tr(E E'), enclosed
    return delta - frob if frob < delta else -math.inf
