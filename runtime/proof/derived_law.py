"""The law in the form the C computes it: one sum of products per output, the same for both observer forms.

::

    dy = y - y_op
    v  = u_op + Kx xh + Ky dy + Kz z          (predictor: Kx = -K, Ky = 0; current: Kx = -(K - K M Cd), Ky = -K M)
    u  = clamp(v, lo, hi);  du = u - u_op
    z+ = z + Tr r + Ty y + Kaw (u - v)        (Tr = Ts, Ty = -Ts Ci; Kaw only for backcalc; clamp: z+ = z when any
                                               input saturated)
    xh+ = F xh + G du + Ly dy                 (predictor: F = Ad - L Cd, G = Bd - L Dd, Ly = L;
                                               current: F = Ad - Ad M Cd, G = Bd, Ly = Ad M)

:func:`derive` gives these coefficients from an artifact in float64 (with them, :class:`DerivedLoop` is
:class:`~gainlink.proof.reference.ReferenceLoop`, tested), or exactly, in balls (what the fixed-point certificate
measures the quantised coefficients against); the fixed-point law quantises the float64 ones
(:mod:`gainlink.laws.fixed.gains`), and :class:`DerivedLoop` on the quantised values, with the samples clipped to
the declared ranges, is the float64 law the fixed-point certificate bounds the integer law against.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..shipping.artifact import Artifact
from .ball import balls, precise
from .reference import StepResult, Trace


@dataclass(frozen=True)
class DerivedLaw:
    """The coefficients of the law as the C computes it (see the module docstring); real values.

    ``Tr`` (q) and ``Ty`` (q x p) are the integrators' gains on the absolute reference and sample; ``lo``, ``hi``
    the limits; ``y_min``/``y_max``, ``r_min``/``r_max`` the ranges samples are clipped to (None: no clip).
    """

    F: np.ndarray
    G: np.ndarray
    Ly: np.ndarray
    Kx: np.ndarray
    Ky: np.ndarray
    Kz: np.ndarray
    Tr: np.ndarray
    Ty: np.ndarray
    Kaw: np.ndarray
    u_op: np.ndarray
    y_op: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    xh0: np.ndarray
    z0: np.ndarray
    anti_windup: str
    y_min: np.ndarray | None = None
    y_max: np.ndarray | None = None
    r_min: np.ndarray | None = None
    r_max: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.F.shape[0]

    @property
    def m(self) -> int:
        return self.G.shape[1]

    @property
    def p(self) -> int:
        return self.Ly.shape[1]

    @property
    def q(self) -> int:
        return self.Tr.shape[0]

    def with_ranges(self, ranges: dict | None) -> DerivedLaw:
        """The same law with samples clipped to ``ranges`` (keys y_min, y_max, r_min, r_max; None: no clip)."""
        keys = ("y_min", "y_max", "r_min", "r_max")
        values = {k: None if ranges is None or ranges.get(k) is None else np.asarray(ranges[k], float) for k in keys}
        return replace(self, **values)


def derive(a: Artifact, *, exact: bool = False) -> DerivedLaw:
    """The law's coefficients from an artifact (either observer form): in float64, or with ``exact`` in balls
    (:mod:`.ball`), each containing the exact value of the formulas on the artifact's numbers (the law the design
    means; the float64 products and differences are rounded)."""
    return _derive_balls(a) if exact else _derive(a, np.asarray)


@precise
def _derive_balls(a: Artifact) -> DerivedLaw:
    return _derive(a, balls)


def _derive(a: Artifact, conv) -> DerivedLaw:
    Ad, Bd, Cd, Dd, K, L = (conv(x) for x in (a.Ad, a.Bd, a.Cd, a.Dd, a.K, a.L))
    if a.observer_form == "current":
        M = conv(a.M)
        KM = K @ M
        Kx, Ky = -(K - KM @ Cd), -KM
        Lrow = Ad @ M
        F, G = Ad - Lrow @ Cd, Bd.copy()
    else:
        Kx, Ky = -K, np.zeros((a.m, a.p))
        Lrow = L
        F, G = Ad - L @ Cd, Bd - L @ Dd
    return DerivedLaw(
        F=F,
        G=G,
        Ly=Lrow.copy(),
        Kx=Kx,
        Ky=Ky,
        Kz=-conv(a.Ki),
        Tr=np.full(a.q, a.Ts),
        Ty=-a.Ts * a.Ci,
        Kaw=a.Kaw if a.anti_windup == "backcalc" else np.zeros((a.q, a.m)),
        u_op=a.u_op,
        y_op=a.y_op,
        lo=a.u_min,
        hi=a.u_max,
        xh0=a.xh0,
        z0=a.z0,
        anti_windup=a.anti_windup,
    )


class DerivedLoop:
    """The float64 law on :class:`DerivedLaw` coefficients (``step``, ``run``, ``xh``, ``z``, ``reset`` as
    :class:`~gainlink.proof.reference.ReferenceLoop`). Samples outside the law's ranges are clipped to them."""

    def __init__(self, law: DerivedLaw) -> None:
        self.law = law
        self.safe_u = np.minimum(np.maximum(law.u_op, law.lo), law.hi)
        self.reset()

    def reset(self) -> None:
        """Back to the initial estimate and integrator."""
        self.xh = self.law.xh0.astype(float).copy()
        self.z = self.law.z0.astype(float).copy()

    def step(self, y: np.ndarray, r: np.ndarray | None = None) -> StepResult:
        """One step on the absolute sample ``y`` (p) and reference ``r`` (q)."""
        c = self.law
        y = np.asarray(y, dtype=float).reshape(c.p)
        r = np.zeros(c.q) if r is None else np.asarray(r, dtype=float).reshape(c.q)
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(r))):
            safe = self.safe_u.copy()
            return StepResult(u=safe, saturated=np.zeros(c.m, dtype=bool), fault=True, v=safe.copy())
        if c.y_min is not None:
            y = np.minimum(np.maximum(y, c.y_min), c.y_max)
        if c.r_min is not None:
            r = np.minimum(np.maximum(r, c.r_min), c.r_max)
        dy = y - c.y_op
        v = c.u_op + c.Kx @ self.xh + c.Ky @ dy + c.Kz @ self.z
        u = np.minimum(np.maximum(v, c.lo), c.hi)
        saturated = u != v
        z = self.z + c.Tr * r + c.Ty @ y + c.Kaw @ (u - v)
        if c.anti_windup == "clamp" and saturated.any():
            z = self.z
        self.xh = c.F @ self.xh + c.G @ (u - c.u_op) + c.Ly @ dy
        self.z = z
        return StepResult(u=u, saturated=saturated, fault=False, v=v)

    def run(self, Y: np.ndarray, R: np.ndarray | None = None) -> Trace:
        """One step per row of ``Y`` (N, p) and ``R`` (N, q) from the current state."""
        c = self.law
        Y = np.asarray(Y, dtype=float).reshape(-1, c.p)
        N = Y.shape[0]
        R = np.zeros((N, c.q)) if R is None else np.asarray(R, dtype=float).reshape(N, c.q)
        U, S = np.empty((N, c.m)), np.empty((N, c.m), dtype=bool)
        XH, Z, F = np.empty((N, c.n)), np.empty((N, c.q)), np.empty(N, dtype=bool)
        for k in range(N):
            res = self.step(Y[k], R[k])
            U[k], S[k], F[k] = res.u, res.saturated, res.fault
            XH[k], Z[k] = self.xh, self.z
        return Trace(u=U, saturated=S, xh=XH, z=Z, fault=F)
