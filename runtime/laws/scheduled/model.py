"""The scheduled C loop's float32 arithmetic (``firmware/src/gl_sched.c``), reproduced in numpy bit for bit.

The C runs the law of :mod:`gainlink.laws.scheduled.reference` on the float32 tables of
:func:`gainlink.laws.scheduled.codegen.tables` (no derivation on the target: the per-point coefficients are
the artifact's, rounded once). Each operation here is the C's, in the C's order (``gl_sched.h`` states it):
float32 ``+ - /`` correctly rounded (numpy float32 scalars), every multiply-add one correctly rounded ``fmaf``
(:func:`gainlink.laws.lq.model.fma32_exact`), each interpolated coefficient ``fmaf(lam, X[i+1] - X[i], X[i])``
and each sum a product of its first terms followed by one ``fmaf`` per further term. In the predictor form the C
skips ``Ky`` (zero there); so does this model.

:class:`ScheduledFloat32Loop` has the interface of :class:`~gainlink.laws.scheduled.reference.ScheduledLoop`
(``step``, ``run``, ``reset``, ``state``), so either can close a loop or be compared step by step.
"""

from __future__ import annotations

import numpy as np

from ...shipping.artifact import Artifact
from ..lq.model import fma32_exact
from .codegen import tables
from .reference import (
    SIGMA_CLIPPED,
    SIGMA_HELD,
    SIGMA_RATE,
    ScheduledState,
    ScheduledStep,
    ScheduledTrace,
)

_F32 = np.float32


def _f(x: float) -> float:
    """``x`` rounded to float32 (kept as a Python float)."""
    return float(_F32(x))


def _sub(a: float, b: float) -> float:
    return float(_F32(a) - _F32(b))


def _add(a: float, b: float) -> float:
    return float(_F32(a) + _F32(b))


def _mul(a: float, b: float) -> float:
    return float(_F32(a) * _F32(b))


def _div(a: float, b: float) -> float:
    return float(_F32(a) / _F32(b))


class ScheduledFloat32Loop:
    """The scheduled C step in float32 (module docstring), with its state in :attr:`state` (float32 values).

    Parameters
    ----------
    artifact : Artifact
        A scheduled (schema-2) artifact.
    """

    def __init__(self, artifact: Artifact) -> None:
        if artifact.schedule is None:
            raise ValueError(f"artifact {artifact.name} is not scheduled: use gainlink.laws.lq.model")
        self.a = artifact
        S = artifact.schedule
        t = {k: np.asarray(v, dtype=np.float64) for k, v in tables(artifact).items()}
        self.t = t
        self.S = t["S"].tolist()
        self.external = S.source == "external"
        self.index = S.index
        self.e = len(S.external)
        self.filtered = S.filter_alpha != 1.0
        self.rate_limited = S.rate_max is not None
        self.current = artifact.observer_form == "current"
        self.reset()

    def reset(self) -> None:
        """Back to the start (``gl_sched_reset``): zero increments, sigma at the first point, not started."""
        a = self.a
        s0 = self.S[0]
        self.state = ScheduledState(np.zeros(a.n), np.array(self._trim(0, 0.0)), np.zeros(a.p), np.zeros(a.q),
                                    s0, s0, False)  # fmt: skip

    def _interval(self, sigma: float) -> tuple[int, float]:
        S = self.S
        i = 0
        while i + 2 < len(S) and sigma >= S[i + 1]:
            i += 1
        return i, _div(_sub(sigma, S[i]), _sub(S[i + 1], S[i]))

    def _lerp(self, name: str, i: int, lam: float) -> list[float]:
        x0, x1 = self.t[name][i].tolist(), self.t[name][i + 1].tolist()
        return [fma32_exact(lam, _sub(b, a), a) for a, b in zip(x0, x1, strict=True)]

    def _trim(self, i: int, lam: float) -> list[float]:
        lo, hi = self.t["u_min"].tolist(), self.t["u_max"].tolist()
        return [lo[k] if u < lo[k] else (hi[k] if u > hi[k] else u) for k, u in enumerate(self._lerp("u_op", i, lam))]

    def safe_command(self) -> np.ndarray:
        """The command on a refused sample: ``u_op`` at the held sigma, clamped."""
        return np.array(self._trim(*self._interval(self.state.sigma)))

    def step(self, y, r=None, s=None) -> ScheduledStep:
        """One C step on ``y`` (p), ``r`` (q), ``s`` (e), cast to float32 as the C API does."""
        a = self.a
        with np.errstate(over="ignore"):
            ys = np.asarray(y, dtype=float).reshape(a.p).astype(_F32).astype(float).tolist()
            rs = (np.zeros(a.q) if r is None else np.asarray(r, float).reshape(a.q)).astype(_F32).astype(float).tolist()
            ss = (np.zeros(self.e) if s is None else np.asarray(s, float).reshape(self.e)).astype(_F32).astype(float)
        if not (np.all(np.isfinite(ys)) and np.all(np.isfinite(rs))):
            u = self.safe_command()
            return ScheduledStep(u, np.zeros(a.m, dtype=bool), True, u.copy(), self.state.sigma, 0)
        sigma, flags = self._sigma(float(ss[self.index]) if self.external else ys[self.index])
        i, lam = self._interval(sigma)
        st = self.state
        if not st.started:
            st.y_prev, st.u_prev = np.array(ys), np.array(self._trim(i, lam))
            st.e_prev, st.delta, st.started = np.zeros(a.q), np.zeros(a.n), True
        c = {k: self._lerp(k, i, lam) for k in ("Kx", "Ky", "Kz", "F", "G", "Ly")}
        dy = [_sub(yk, pk) for yk, pk in zip(ys, st.y_prev.tolist(), strict=True)]
        u, v, du = self._command(c, dy)
        st.delta = np.array(self._estimate(c, du, dy))
        Ci = self.t["Ci"].tolist()
        e_prev = []
        for j in range(a.q):
            e = rs[j]
            for k in range(a.p):
                e = fma32_exact(-Ci[j * a.p + k], ys[k], e)
            e_prev.append(e)
        st.e_prev, st.y_prev, st.u_prev = np.array(e_prev), np.array(ys), np.array(u)
        return ScheduledStep(np.array(u), np.array(u) != np.array(v), False, np.array(v), sigma, flags)

    def _command(self, c: dict, dy: list[float]) -> tuple[list[float], list[float], list[float]]:
        """``v = u_prev - (Kx delta + Ky dy + Kz e_prev)``, clamped; ``du = u - u_prev``."""
        a, st = self.a, self.state
        delta, e_prev, u_prev = st.delta.tolist(), st.e_prev.tolist(), st.u_prev.tolist()
        lo, hi = self.t["u_min"].tolist(), self.t["u_max"].tolist()
        u, v, du = [], [], []
        for i in range(a.m):
            acc = _mul(c["Kx"][i * a.n], delta[0])
            for j in range(1, a.n):
                acc = fma32_exact(c["Kx"][i * a.n + j], delta[j], acc)
            if self.current:
                for k in range(a.p):
                    acc = fma32_exact(c["Ky"][i * a.p + k], dy[k], acc)
            for j in range(a.q):
                acc = fma32_exact(c["Kz"][i * a.q + j], e_prev[j], acc)
            vi = _sub(u_prev[i], acc)
            ui = lo[i] if vi < lo[i] else (hi[i] if vi > hi[i] else vi)
            u.append(ui)
            v.append(vi)
            du.append(_sub(ui, u_prev[i]))
        return u, v, du

    def _estimate(self, c: dict, du: list[float], dy: list[float]) -> list[float]:
        """``delta = F delta + G du + Ly dy``, one row at a time."""
        a = self.a
        delta = self.state.delta.tolist()
        out = []
        for i in range(a.n):
            acc = _mul(c["F"][i * a.n], delta[0])
            for j in range(1, a.n):
                acc = fma32_exact(c["F"][i * a.n + j], delta[j], acc)
            for k in range(a.m):
                acc = fma32_exact(c["G"][i * a.m + k], du[k], acc)
            for k in range(a.p):
                acc = fma32_exact(c["Ly"][i * a.p + k], dy[k], acc)
            out.append(acc)
        return out

    def _sigma(self, raw: float) -> tuple[float, int]:
        """Hold, clip, filter and rate-limit sigma as ``next_sigma`` of gl_sched.c; updates the state."""
        st, S = self.state, self.S
        if not np.isfinite(raw):
            return st.sigma, SIGMA_HELD
        c = S[0] if raw < S[0] else (S[-1] if raw > S[-1] else raw)
        flags = SIGMA_CLIPPED if c != raw else 0
        if not st.started:
            st.sigma_f = st.sigma = c
            return c, flags
        if self.filtered:
            st.sigma_f = fma32_exact(float(self.t["alpha"]), _sub(c, st.sigma_f), st.sigma_f)
        else:
            st.sigma_f = c
        step = float(self.t["rate_step"])
        d = _sub(st.sigma_f, st.sigma)
        if self.rate_limited and abs(d) > step:
            st.sigma, flags = _add(st.sigma, step if d > 0 else -step), flags | SIGMA_RATE
        else:
            st.sigma = st.sigma_f
        return st.sigma, flags

    def run(self, Y, R=None, Sx=None) -> ScheduledTrace:
        """One step per row of ``Y`` (N, p), ``R`` (N, q) and ``Sx`` (N, e) from the current state."""
        a = self.a
        Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
        N = Y.shape[0]
        R = np.zeros((N, a.q)) if R is None else np.asarray(R, dtype=float).reshape(N, a.q)
        Sx = np.zeros((N, self.e)) if Sx is None else np.asarray(Sx, dtype=float).reshape(N, self.e)
        steps, states = [], []
        for k in range(N):
            steps.append(self.step(Y[k], R[k], Sx[k]))
            states.append(self.state.vector())
        return ScheduledTrace(
            u=np.array([s.u for s in steps]).reshape(N, a.m),
            saturated=np.array([s.saturated for s in steps], dtype=bool).reshape(N, a.m),
            fault=np.array([s.fault for s in steps], dtype=bool),
            sigma=np.array([s.sigma for s in steps]),
            sigma_flags=np.array([s.sigma_flags for s in steps], dtype=int),
            state=np.array(states).reshape(N, -1),
        )
