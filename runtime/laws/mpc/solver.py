"""The MPC law's solver: ADMM whose primal step is a Riccati backward/forward pass on per-stage gains cached at design
time (docs/design.md, "MPC (the fourth law)"), written once for both arithmetics (:mod:`.arith`).

The QP (deviations about the operating point; ``x0`` the estimate and the integrators)::

    min 1/2 sum_{k<N} (x_k' Q x_k + u_k' R u_k) + 1/2 x_N' P x_N + sum_{k=1..N} w/2 dist(Hx x_k, [lo_x, hi_x])^2
    s.t. x_{k+1} = A x_k + B u_k,  lo_u <= u_k <= hi_u

split as ``u_k = zu_k`` (the box: a projection) and ``Hx x_{k+1} = zx_k`` (the soft box: its proximal step), scaled
duals ``yu``, ``yx``. One iteration, in this order (``firmware/src/gl_mpc.c`` runs the same operations)::

    backward  p = rho_x Hx'(yx_{N-1} - zx_{N-1})                              (x_N's slack)
              for k = N-1 .. 0:  g = rho (yu_k - zu_k) + B' p ;  d_k = C1_k g
                                 k > 0:  p = rho_x Hx'(yx_{k-1} - zx_{k-1}) + A' p - K_k' g
    forward   x = x0;  for k = 0 .. N-1:  u_k = -d_k - K_k x ;  x = A x + B u_k ;  c_k = Hx x
    slacks    v = u_k + yu_k ; zu_k = clamp(v, lo_u, hi_u) ; e = u_k - zu_k ; yu_k = yu_k + e
              v = c_k + yx_k ; zx_k = v - kappa (v - hi_x) above, v - kappa (v - lo_x) below, else v ; likewise yx
    stop      every |e| <= tol scale and rho |z - z_before| <= tol rho scale (per input and box row)

each sum a chain from its first (constant) term, every product-sum one fused multiply-add, terms in the order
written. ``kappa = w / (rho_x + w)``. The solver stops at convergence or at ``max_iter`` (the cap): a step's cost is
bounded by the cap. The warm start for the next step is the slacks and duals shifted one stage (the last kept).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .arith import Arith
from .block import Mpc


@dataclass
class Tables:
    """An :class:`~gainlink.laws.mpc.block.Mpc` in one arithmetic's numbers (the C's float32 tables)."""

    A: np.ndarray
    B: np.ndarray
    negK: np.ndarray  # (N, m, nx): -K_k, as the C multiplies it
    C1: np.ndarray
    Hx: np.ndarray
    lo_u: np.ndarray
    hi_u: np.ndarray
    lo_x: np.ndarray
    hi_x: np.ndarray
    rho: float
    rho_x: float
    kappa: float
    eps_pu: np.ndarray
    eps_du: np.ndarray
    eps_px: np.ndarray
    eps_dx: np.ndarray
    max_iter: int

    @classmethod
    def of(cls, mpc: Mpc, ar: Arith) -> Tables:
        """The tables of ``mpc`` in ``ar`` (float32: each number rounded once from float64, as the export does)."""
        v = ar.value
        eps = mpc.eps
        big = np.finfo(np.float32).max  # an infinite side of a box: never binds, finite in every arithmetic
        return cls(A=v(mpc.A), B=v(mpc.B), negK=-v(mpc.K), C1=v(mpc.C1), Hx=v(mpc.Hx),
                   lo_u=v(mpc.lo_u), hi_u=v(mpc.hi_u), lo_x=v(np.maximum(mpc.lo_x, -big)),
                   hi_x=v(np.minimum(mpc.hi_x, big)), rho=float(v(mpc.rho)), rho_x=float(v(mpc.rho_state)),
                   kappa=float(v(mpc.kappa)), eps_pu=v(eps["pu"]), eps_du=v(eps["du"]), eps_px=v(eps["px"]),
                   eps_dx=v(eps["dx"]), max_iter=mpc.max_iter)  # fmt: skip


@dataclass
class Workspace:
    """The solver's state between steps: the slacks and scaled duals of every stage (the warm start)."""

    zu: np.ndarray  # (N, m)
    yu: np.ndarray
    zx: np.ndarray  # (N, nc): the box rows of x_1 .. x_N
    yx: np.ndarray

    @classmethod
    def zeros(cls, N: int, m: int, nc: int) -> Workspace:
        return cls(np.zeros((N, m)), np.zeros((N, m)), np.zeros((N, nc)), np.zeros((N, nc)))

    def copy(self) -> Workspace:
        return Workspace(self.zu.copy(), self.yu.copy(), self.zx.copy(), self.yx.copy())

    def flat(self) -> np.ndarray:
        """``zu, yu, zx, yx`` one after the other (the record's ``ws``)."""
        return np.concatenate([self.zu.ravel(), self.yu.ravel(), self.zx.ravel(), self.yx.ravel()])

    @classmethod
    def from_flat(cls, w: np.ndarray, N: int, m: int, nc: int) -> Workspace:
        a, b = N * m, N * nc
        w = np.asarray(w, dtype=np.float64)
        parts = np.split(w, [a, 2 * a, 2 * a + b])
        return cls(*(p.reshape(N, -1).copy() for p in parts))

    def shift(self) -> None:
        """The warm start for the next step: every stage one earlier, the last kept."""
        for a in (self.zu, self.yu, self.zx, self.yx):
            a[:-1] = a[1:].copy()


@dataclass(frozen=True)
class Solution:
    """What one solve returns: the moves and states of the last iteration, the iterations run and whether the
    stopping test held (False: the cap stopped it)."""

    u: np.ndarray  # (N, m)
    x: np.ndarray  # (N + 1, nx)
    iterations: int
    converged: bool


def _backward(t: Tables, ar: Arith, ws: Workspace) -> np.ndarray:
    """The linear terms d_k of every stage (module docstring)."""
    N, m = ws.zu.shape
    d = np.zeros((N, m))
    p = _box_term(t, ar, ws, N - 1)
    for k in range(N - 1, -1, -1):
        g = ar.mul(t.rho, ar.sub(ws.yu[k], ws.zu[k]))
        g = ar.matvec(t.B.T, p, g)
        d[k] = ar.matvec(t.C1[k], g, ar.value(np.zeros(m)))
        if k > 0:
            p = ar.matvec(t.negK[k].T, g, ar.matvec(t.A.T, p, _box_term(t, ar, ws, k - 1)))
    return d


def _box_term(t: Tables, ar: Arith, ws: Workspace, j: int) -> np.ndarray:
    """``rho_x Hx' (yx_j - zx_j)``: the linear term of x_{j+1}'s slack (zeros without boxes)."""
    acc = ar.value(np.zeros(t.A.shape[0]))
    if t.Hx.shape[0] == 0:
        return acc
    w = ar.mul(t.rho_x, ar.sub(ws.yx[j], ws.zx[j]))
    return ar.matvec(t.Hx.T, w, acc)


def _forward(t: Tables, ar: Arith, x0: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Moves, states and box rows of the stages from x0."""
    N, m = d.shape
    nx = x0.size
    u, x, c = np.zeros((N, m)), np.zeros((N + 1, nx)), np.zeros((N, t.Hx.shape[0]))
    x[0] = x0
    for k in range(N):
        u[k] = ar.matvec(t.negK[k], x[k], -d[k])
        x[k + 1] = ar.matvec(t.B, u[k], ar.matvec(t.A, x[k], ar.value(np.zeros(nx))))
        if t.Hx.shape[0]:
            c[k] = ar.matvec(t.Hx, x[k + 1], ar.value(np.zeros(t.Hx.shape[0])))
    return u, x, c


def _soft(ar: Arith, v: np.ndarray, lo: np.ndarray, hi: np.ndarray, kappa: float) -> np.ndarray:
    """The soft box's proximal step: outside the box, back ``kappa`` of the way to it."""
    above = ar.fma(-kappa, ar.sub(v, hi), v)
    below = ar.fma(-kappa, ar.sub(v, lo), v)
    return np.where(v > hi, above, np.where(v < lo, below, v))


def _update(ar: Arith, prim, y, z, zold, eps_p, eps_d, rho) -> bool:
    """The dual step and both residual tests (``prim - z`` is the primal residual)."""
    e = ar.sub(prim, z)
    y[...] = ar.add(y, e)
    dual = ar.mul(rho, np.abs(ar.sub(z, zold)))
    return bool(np.all(np.abs(e) <= eps_p) and np.all(dual <= eps_d))


def _slacks(t: Tables, ar: Arith, ws: Workspace, u: np.ndarray, c: np.ndarray) -> bool:
    """Slack and dual steps of every stage; True when both residuals are within their tolerances."""
    zold = ws.zu.copy()
    v = ar.add(u, ws.yu)
    ws.zu[...] = np.where(v < t.lo_u, t.lo_u, np.where(v > t.hi_u, t.hi_u, v))
    done = _update(ar, u, ws.yu, ws.zu, zold, t.eps_pu, t.eps_du, t.rho)
    if t.Hx.shape[0]:
        zold = ws.zx.copy()
        ws.zx[...] = _soft(ar, ar.add(c, ws.yx), t.lo_x, t.hi_x, t.kappa)
        done = _update(ar, c, ws.yx, ws.zx, zold, t.eps_px, t.eps_dx, t.rho_x) and done
    return done


def solve(t: Tables, ar: Arith, ws: Workspace, x0: np.ndarray, *, iterations: int | None = None) -> Solution:
    """Iterate from the warm start ``ws`` (updated in place) until the stopping test holds or the cap; with
    ``iterations``, exactly that many (a replay of another run's count: termination is discontinuous, so two
    arithmetics are compared on the same count)."""
    cap = t.max_iter if iterations is None else iterations
    for it in range(1, cap + 1):
        d = _backward(t, ar, ws)
        u, x, c = _forward(t, ar, x0, d)
        done = _slacks(t, ar, ws, u, c)
        if done and iterations is None:
            return Solution(u=u, x=x, iterations=it, converged=True)
    return Solution(u=u, x=x, iterations=cap, converged=done)
