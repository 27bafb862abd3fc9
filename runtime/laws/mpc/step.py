"""One step of the MPC law (docs/design.md, "MPC (the fourth law)"), written once for both arithmetics (:mod:`.arith`):
the observer and integrators of the observer-based law around the solver of :mod:`.solver`.

On the absolute sample ``y`` (p) and reference ``r`` (q), in this order (``firmware/src/gl_mpc.c``)::

    y or r not finite: the safe command (u_op clamped), FAULT, nothing changes (estimate, integrators, warm start)
    dy = y - y_op
    current form: xc = xh + M (dy - Cd xh);  the MPC's x0 = [xc; z]   (predictor: [xh; z])
    solve from x0 (the warm start): moves u_0 .. u_(N-1)
    v = u_op + u_0;  u = clamp(v, u_min, u_max)          (at the cap: the projected first move, flagged CAPPED)
    sat bit j: u_j clamped, or the first move's slack on input j's box
    e = r - Ci y;  z = z + Ts e  (+ Kaw (u - v): backcalc; only if u == v: clamp)
    du = u - u_op
    predictor: xh = Ad xh + Bd du + L (dy - Cd xh - Dd du);  current: xh = Ad xc + Bd du
    the warm start shifted one stage

Each sum a chain from its first (constant) term, one fused multiply-add a term in the order written (``dy - Cd xh
- Dd du``: from ``dy``, minus each ``Cd`` term, then each ``Dd`` term; ``Ad xh + Bd du + L innov``: from zero).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...shipping.artifact import Artifact
from .. import flags
from .arith import Arith
from .solver import Solution, Tables, Workspace, solve


@dataclass(frozen=True)
class MpcStep:
    """One step: the command, the unsaturated ``v``, the saturation bits, whether the sample was refused, the
    iterations the solver ran and whether it stopped on its tolerances."""

    u: np.ndarray
    v: np.ndarray
    sat: int
    fault: bool
    iterations: int = 0
    converged: bool = True
    solution: Solution | None = None

    @property
    def flags(self) -> int:
        """The status flags of the step (the one table)."""
        return flags.FAULT if self.fault else (0 if self.converged else flags.CAPPED)


@dataclass(frozen=True)
class MpcTrace:
    """A block of steps: row k holds step k's command, saturation bits, status flags, iterations and the law's
    state after it (:meth:`MpcLoop.state`)."""

    u: np.ndarray
    sat: np.ndarray
    flags: np.ndarray
    iterations: np.ndarray
    state: np.ndarray

    @property
    def saturated(self) -> np.ndarray:
        """(N, m): input j clamped at step k (from :attr:`sat`)."""
        return ((self.sat[:, None] >> np.arange(self.u.shape[1])) & 1).astype(bool)

    @property
    def fault(self) -> np.ndarray:
        """Refused steps."""
        return (self.flags & flags.FAULT) != 0


class Law:
    """The law's numbers in one arithmetic: the observer-based law's and the solver's tables."""

    def __init__(self, a: Artifact, ar: Arith) -> None:
        v = ar.value
        self.ar, self.a = ar, a
        self.t = Tables.of(a.mpc, ar)
        self.Ad, self.Bd, self.Cd, self.Dd, self.L = v(a.Ad), v(a.Bd), v(a.Cd), v(a.Dd), v(a.L)
        self.M = None if a.M is None else v(a.M)
        self.Ci, self.Kaw, self.Ts = v(a.Ci), v(a.Kaw), float(v(a.Ts))
        self.u_op, self.y_op, self.u_min, self.u_max = v(a.u_op), v(a.y_op), v(a.u_min), v(a.u_max)
        self.safe = np.minimum(np.maximum(self.u_op, self.u_min), self.u_max)


class MpcLoop:
    """The MPC law of ``artifact`` in arithmetic ``ar``, with its state: ``xh`` (n), ``z`` (q) and the warm start
    ``ws`` (:class:`~.solver.Workspace`)."""

    def __init__(self, artifact: Artifact, ar: Arith) -> None:
        self.law = Law(artifact, ar)
        self.a, self.ar = artifact, ar
        self.reset()

    def reset(self) -> None:
        """The start: the artifact's initial estimate and integrators, a cold warm start."""
        a = self.a
        self.xh, self.z = self.ar.value(a.xh0), self.ar.value(a.z0)
        self.ws = Workspace.zeros(a.mpc.horizon, a.m, a.mpc.nc)

    def state(self) -> np.ndarray:
        """The law's whole state: ``xh, z`` and the warm start (``zu, yu, zx, yx``)."""
        return np.concatenate([self.xh, self.z, self.ws.flat()])

    def set_state(self, state: np.ndarray) -> None:
        """Put the law in ``state`` (:meth:`state`'s layout), e.g. the C's own, for a one-step check."""
        a = self.a
        n, q = a.n, a.q
        state = np.asarray(state, dtype=np.float64)
        self.xh, self.z = state[:n].copy(), state[n : n + q].copy()
        self.ws = Workspace.from_flat(state[n + q :], a.mpc.horizon, a.m, a.mpc.nc)

    def step(self, y, r=None, *, iterations: int | None = None) -> MpcStep:
        """One sample (module docstring); ``iterations`` replays that many solver iterations (another run's
        count) instead of stopping on the tolerances."""
        lw, ar, a = self.law, self.ar, self.a
        ys = ar.value(np.asarray(y, dtype=np.float64).reshape(a.p))
        rs = ar.value(np.zeros(a.q) if r is None else np.asarray(r, dtype=np.float64).reshape(a.q))
        if not (np.all(np.isfinite(ys)) and np.all(np.isfinite(rs))):
            return MpcStep(u=lw.safe.copy(), v=lw.safe.copy(), sat=0, fault=True)
        dy = ar.sub(ys, lw.y_op)
        xe = self.xh
        if lw.M is not None:  # current form: the filtered estimate
            innov = ar.matvec(-lw.Cd, self.xh, dy)
            xe = ar.matvec(lw.M, innov, self.xh)
        sol = solve(lw.t, ar, self.ws, np.concatenate([xe, self.z]), iterations=iterations)
        v = ar.add(lw.u_op, sol.u[0])
        u = np.minimum(np.maximum(v, lw.u_min), lw.u_max)
        on_box = (self.ws.zu[0] == lw.t.lo_u) | (self.ws.zu[0] == lw.t.hi_u)
        sat = int(np.sum(((u != v) | on_box).astype(np.int64) << np.arange(a.m)))
        self.z = self._integrate(ys, rs, u, v)
        du = ar.sub(u, lw.u_op)
        self.xh = self._estimate(xe, dy, du)
        self.ws.shift()
        return MpcStep(u=u, v=v, sat=sat, fault=False, iterations=sol.iterations, converged=sol.converged,
                       solution=sol)  # fmt: skip

    def _integrate(self, ys, rs, u, v) -> np.ndarray:
        lw, ar, a = self.law, self.ar, self.a
        if a.q == 0:
            return self.z
        e = ar.matvec(-lw.Ci, ys, rs)
        if a.anti_windup == "clamp" and np.any(u != v):
            return self.z
        z = ar.fma(lw.Ts, e, self.z)
        if a.anti_windup == "backcalc":
            z = ar.matvec(lw.Kaw, ar.sub(u, v), z)
        return z

    def _estimate(self, xe, dy, du) -> np.ndarray:
        lw, ar = self.law, self.ar
        zero = ar.value(np.zeros(self.a.n))
        if lw.M is not None:
            return ar.matvec(lw.Bd, du, ar.matvec(lw.Ad, xe, zero))
        innov = ar.matvec(-lw.Dd, du, ar.matvec(-lw.Cd, self.xh, dy))
        return ar.matvec(lw.L, innov, ar.matvec(lw.Bd, du, ar.matvec(lw.Ad, self.xh, zero)))

    def run(self, Y, R=None) -> MpcTrace:
        """One step per row of ``Y`` (N, p) and ``R`` (N, q) from the current state."""
        a = self.a
        Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
        N = Y.shape[0]
        R = np.zeros((N, a.q)) if R is None else np.asarray(R, dtype=float).reshape(N, a.q)
        U, S, F, IT = np.empty((N, a.m)), np.zeros(N, np.int64), np.zeros(N, np.int64), np.zeros(N, np.int64)
        X = np.empty((N, self.state().size))
        for k in range(N):
            res = self.step(Y[k], R[k])
            U[k], S[k], F[k], IT[k], X[k] = res.u, res.sat, res.flags, res.iterations, self.state()
        return MpcTrace(u=U, sat=S, flags=F, iterations=IT, state=X)
