"""The C loop's float32 arithmetic, reproduced in numpy (no toolchain needed).

The firmware derives its coefficient stream in double from the float32 gain set and rounds each
coefficient once to float32 (``gl_coeffs_derive`` in ``firmware/src/gl_gains_check.c``); each step is
then a chain of float32 fused multiply-adds over that stream in a fixed order (``gl_step_core`` in
``firmware/src/gl_loop.c``: ``dy = y - y_op`` first, the feedback sum in deviations, ``u_op`` added
once, ``du = u - u_op`` into the estimate). :class:`Float32Loop` performs the same derivation and the
same chain:

- a float32 product of two float32 numbers is exact in float64 and is rounded once;
- ``fmaf(a, b, c)`` is ``a*b`` (exact in float64) plus ``c``, rounded to float64 and then to float32.
  The two roundings differ from one correctly rounded ``fmaf`` only when the float64 sum lands exactly
  on a float32 rounding midpoint while the exact sum does not; a step with a sum on a midpoint is redone with
  correctly rounded operations (:func:`fma32_exact`), so results are those of the C bit for bit for normal
  numbers (tested against the host build). float32 subnormal results (below 1.2e-38) are not treated specially.

Each step runs as straight-line Python written for the artifact's dimensions (:mod:`.step`, as the export's
``gl_step.h``); the term-by-term interpreter (:meth:`Float32Loop._core`) is the exact path.

It exists so that ``gainlink design`` can measure what float32 costs a design in closed loop without a
compiler (the check runs for every design; building the firmware takes seconds).
"""

from __future__ import annotations

import math
from array import array

import numpy as np

from ...proof.reference import StepResult, Trace
from ...shipping.artifact import Artifact
from ...shipping.law_c import require_structure
from .step import MID_HALF, MID_MASK, compile_step

_F32 = np.float32


def round32(x: np.ndarray | float) -> np.ndarray:
    """Round float64 values to float32 and back (the values stay float64 arrays)."""
    return np.asarray(x, dtype=np.float64).astype(_F32).astype(np.float64)


def fma32_exact(a: float, b: float, c: float) -> float:
    """``fmaf(a, b, c)`` for float32 values given as Python floats, correctly rounded."""
    prod = a * b  # exact: 24-bit by 24-bit significands
    s = prod + c
    r = float(_F32(s))
    if s != r and _is_midpoint(s):
        bb = s - prod
        err = (prod - (s - bb)) + (c - bb)  # TwoSum: the exact sum is s + err
        if err != 0.0:
            below = r if r < s else float(np.nextafter(_F32(r), _F32(-np.inf)))
            above = float(np.nextafter(_F32(below), _F32(np.inf)))
            r = above if err > 0 else below
    return r


def _is_midpoint(s: float) -> bool:
    return bool((np.float64(s).view(np.uint64) & MID_MASK) == MID_HALF)


class _ExactRounding:
    """float32 multiply and a correctly rounded fmaf on Python floats: the exact path of :meth:`Float32Loop._core`."""

    def __init__(self) -> None:
        self.buf = array("f", [0.0])

    def mul(self, a: float, b: float) -> float:
        self.buf[0] = a * b
        return self.buf[0]

    @staticmethod
    def fma(a: float, b: float, c: float) -> float:
        return fma32_exact(a, b, c)


def _g(x: np.ndarray) -> np.ndarray:
    """A gain as the C struct stores it: float32, widened to double for the derivation."""
    return round32(x)


class Float32Loop:
    """The C loop's arithmetic for ``artifact``: coefficients derived in double, steps in float32.

    Same interface as :class:`gainlink.proof.reference.ReferenceLoop` (``step``, ``run``, ``xh``, ``z``,
    ``reset``), so either can close a loop.

    Parameters
    ----------
    artifact : Artifact
        A validated gain artifact.
    """

    def __init__(self, artifact: Artifact) -> None:
        require_structure(artifact, "lq", "the float32 law")
        self.a = artifact
        self._derive()
        self.reset()

    def _derive(self) -> None:
        a = self.a
        current = a.observer_form == "current"
        K, Cd, Ad, Bd, Dd = _g(a.K), _g(a.Cd), _g(a.Ad), _g(a.Bd), _g(a.Dd)
        M = _g(a.M) if current else np.zeros((a.n, a.p))
        # Command rows: -(K - (K M) Cd); estimate rows: Ad - Lrow Cd, Bd - Lrow Dd, Lrow (Lrow = L, or Ad M
        # in the current form). Each sum in double in gl_coeffs_derive's order, then one float32 rounding.
        KM = _ordered_matmul(K, M) if current else np.zeros((a.m, a.p))
        Lrow = _ordered_matmul(Ad, M) if current else _g(a.L)
        self.Kx = round32(-_ordered_sub(K, KM, Cd))
        self.Ky = round32(-KM)
        self.Kz = -_g(a.Ki)
        self.lo, self.hi = _g(a.u_min), _g(a.u_max)
        self.Ci = -_g(a.Ci)
        self.Ts = float(round32(a.Ts))
        self.Kaw = _g(a.Kaw)
        self.F = round32(_ordered_sub(Ad, Lrow, Cd))
        self.G = round32(_ordered_sub(Bd, Lrow, Dd))
        self.Ly = round32(Lrow)
        self.u_op, self.y_op = _g(a.u_op), _g(a.y_op)
        self.safe_u = np.minimum(np.maximum(self.u_op, self.lo), self.hi)
        self.current = current
        self.w = self._stream()
        self._fast = compile_step(self.w, n=a.n, m=a.m, p=a.p, q=a.q, current=current, anti_windup=a.anti_windup)

    def _stream(self) -> list[float]:
        """The coefficients in the order gl_step_core consumes them."""
        a = self.a
        w: list[float] = self.y_op.tolist()
        for i in range(a.m):
            w += (
                [float(self.u_op[i])]
                + self.Kx[i].tolist()
                + (self.Ky[i].tolist() if self.current else [])
                + self.Kz[i].tolist()
            )
            w += [float(self.lo[i]), float(self.hi[i])]
        for j in range(a.q):
            w += self.Ci[j].tolist() + [self.Ts] + (self.Kaw[j].tolist() if a.anti_windup == "backcalc" else [])
        for i in range(a.n):
            w += self.F[i].tolist() + self.G[i].tolist() + self.Ly[i].tolist()
        return w

    def reset(self) -> None:
        """Back to the artifact's initial estimate and integrator (rounded to float32)."""
        self.xh = round32(self.a.xh0)
        self.z = round32(self.a.z0)

    def step(self, y: np.ndarray, r: np.ndarray | None = None) -> StepResult:
        """One C step on measurement ``y`` and reference ``r`` (cast to float32 as the C API does)."""
        a = self.a
        # Python floats holding float32 values: the step below is scalar code, where numpy's per-call cost would
        # dominate (this runs in every design's float32 check)
        ys = np.asarray(y, dtype=float).reshape(a.p).astype(_F32).tolist()
        rs = [0.0] * a.q if r is None else np.asarray(r, dtype=float).reshape(a.q).astype(_F32).tolist()
        if not all(map(math.isfinite, ys + rs)):
            return StepResult(
                u=self.safe_u.copy(), saturated=np.zeros(a.m, dtype=bool), fault=True, v=self.safe_u.copy()
            )
        args = (self.xh.tolist(), self.z.tolist(), ys, rs)
        u, v, sat, xh, z, inexact = self._fast(*args)  # gl_step_core unrolled (laws.lq.step)
        if inexact:  # an fmaf sum on a float32 midpoint: double rounding may differ from fmaf's one rounding
            u, v, sat, xh, z = self._core(*args, _ExactRounding())
        self.xh, self.z = np.array(xh), np.array(z)
        return StepResult(u=np.array(u), saturated=np.array(sat, dtype=bool), fault=False, v=np.array(v))

    def _core(self, xh: list, z: list, ys: list, rs: list, rounding) -> tuple[list, list, list, list, list]:
        """gl_step_core: the same operations in the same order over the coefficient stream, interpreted term by
        term (with :class:`_ExactRounding`: the step that :mod:`.step`'s fast path falls back to)."""
        a = self.a
        n, m, p, q = a.n, a.m, a.p, a.q
        mul, fma = rounding.mul, rounding.fma
        w = self.w
        dy = [fma(1.0, ys[k], -w[k]) for k in range(p)]  # y - y_op, one float32 subtraction
        pos = p
        v, u, du, sat = [0.0] * m, [0.0] * m, [0.0] * m, [False] * m
        for i in range(m):
            uop = w[pos]
            acc = mul(w[pos + 1], xh[0])
            pos += 2
            for j in range(1, n):
                acc = fma(w[pos], xh[j], acc)
                pos += 1
            if self.current:
                for k in range(p):
                    acc = fma(w[pos], dy[k], acc)
                    pos += 1
            for j in range(q):
                acc = fma(w[pos], z[j], acc)
                pos += 1
            lo, hi = w[pos], w[pos + 1]
            pos += 2
            v[i] = u[i] = fma(1.0, uop, acc)  # u_op added once to the deviation sum
            if v[i] < lo:
                u[i], sat[i] = lo, True
            elif v[i] > hi:
                u[i], sat[i] = hi, True
            du[i] = fma(1.0, u[i], -uop)
        zn = list(z)
        for j in range(q):
            e = rs[j]
            for k in range(p):
                e = fma(w[pos], ys[k], e)
                pos += 1
            zj = fma(w[pos], e, z[j])
            pos += 1
            if a.anti_windup == "backcalc":
                for k in range(m):
                    zj = fma(w[pos], fma(1.0, u[k], -v[k]), zj)
                    pos += 1
            if a.anti_windup == "clamp" and any(sat):
                zj = z[j]
            zn[j] = zj
        xn = [0.0] * n
        for i in range(n):
            acc = mul(w[pos], xh[0])
            pos += 1
            for j in range(1, n):
                acc = fma(w[pos], xh[j], acc)
                pos += 1
            for k in range(m):
                acc = fma(w[pos], du[k], acc)
                pos += 1
            for k in range(p):
                acc = fma(w[pos], dy[k], acc)
                pos += 1
            xn[i] = acc
        return u, v, sat, xn, zn

    def run(self, Y: np.ndarray, R: np.ndarray | None = None) -> Trace:
        """Run one step per row of ``Y`` (N, p) and ``R`` (N, q); returns a :class:`~gainlink.proof.reference.Trace`."""
        a = self.a
        Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
        N = Y.shape[0]
        R = np.zeros((N, a.q)) if R is None else np.asarray(R, dtype=float).reshape(N, a.q)
        U, S = np.empty((N, a.m)), np.empty((N, a.m), dtype=bool)
        XH, Z, F = np.empty((N, a.n)), np.empty((N, a.q)), np.empty(N, dtype=bool)
        for k in range(N):
            res = self.step(Y[k], R[k])
            U[k], S[k], F[k] = res.u, res.saturated, res.fault
            XH[k], Z[k] = self.xh, self.z
        return Trace(u=U, saturated=S, xh=XH, z=Z, fault=F)


def _ordered_matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B`` in double, each sum accumulated from 0.0 left to right (as the C loops do)."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for k in range(A.shape[1]):
        out = out + A[:, k : k + 1] * B[k : k + 1, :]
    return out


def _ordered_sub(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``A - B @ C`` in double, subtracting the products one index at a time (as the C loops do)."""
    out = A.copy()
    for k in range(B.shape[1]):
        out = out - B[:, k : k + 1] * C[k : k + 1, :]
    return out
