"""The MPC law's QP solved to optimality by a real solver: Clarabel (interior point) on the sparse QP, and a direct
KKT solve for the unconstrained one. These are the references the solver is judged against (docs/design.md,
"MPC (the fourth law)"): with no constraint active the optimum's first move is the LQ law ``-K x`` (the terminal cost
is the DARE solution of the weights), true of the optimum, never of an ADMM iteration.

Variables ``v = [u_0 .. u_(N-1), x_1 .. x_N, s_1 .. s_N]`` (``s_k``: each box row's violation, penalised
``w/2 |s|^2``, so that ``lo <= Hx x_k - s_k <= hi`` gives ``w/2 dist^2``); cost ``1/2 v' H v`` with ``H`` block
diagonal (``R``, then ``Q`` for x_1 .. x_(N-1) and ``P`` for x_N, then ``w I``); dynamics as equalities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...errors import GainlinkError
from .block import Mpc


@dataclass(frozen=True)
class QpSolution:
    """The optimum: moves (N, m), states x_0 .. x_N (N + 1, nx), the cost, the solver's status."""

    u: np.ndarray
    x: np.ndarray
    cost: float
    status: str


def _blocks(mpc: Mpc) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """The cost's Hessian and the dynamics' equality matrix over ``v`` (module docstring)."""
    N, nx, nc = mpc.horizon, mpc.nx, mpc.nc
    H = sp.block_diag([sp.kron(sp.eye(N), mpc.R), sp.kron(sp.eye(N - 1), mpc.Q), mpc.P,
                       mpc.box_weight * sp.eye(N * nc)], format="csc")  # fmt: skip
    # x_{k+1} - A x_k - B u_k = 0 for k = 0 .. N-1 (x_0 given: its term moves to the right-hand side)
    Eu = sp.kron(sp.eye(N), -mpc.B)
    Ex = sp.eye(N * nx) - sp.kron(sp.eye(N, k=-1), mpc.A)
    E = sp.hstack([Eu, Ex, sp.csc_matrix((N * nx, N * nc))], format="csc")
    return H, E


def unconstrained(mpc: Mpc, x0: np.ndarray) -> QpSolution:
    """The QP without its boxes, by one KKT solve (dense LU)."""
    N, nx = mpc.horizon, mpc.nx
    H, E = _blocks(mpc)
    nv = H.shape[0]
    rhs_eq = np.zeros(N * nx)
    rhs_eq[:nx] = mpc.A @ x0
    kkt = np.block([[H.toarray(), E.T.toarray()], [E.toarray(), np.zeros((E.shape[0], E.shape[0]))]])
    sol = np.linalg.solve(kkt, np.concatenate([np.zeros(nv), rhs_eq]))[:nv]
    return _solution(mpc, x0, sol, H, "kkt")


def solve_qp(mpc: Mpc, x0: np.ndarray, *, tol: float = 1e-10) -> QpSolution:
    """The QP with its input box and soft boxes, solved by Clarabel to ``tol`` (its gap and feasibility
    tolerances); GainlinkError when it does not solve."""
    import clarabel

    N, m, nx, nc = mpc.horizon, mpc.B.shape[1], mpc.nx, mpc.nc
    H, E = _blocks(mpc)
    nv = H.shape[0]
    beq = np.zeros(N * nx)
    beq[:nx] = mpc.A @ x0
    rows, b = [E], [beq]
    Iu = sp.hstack([sp.eye(N * m), sp.csc_matrix((N * m, nv - N * m))])
    rows += [Iu, -Iu]
    b += [np.tile(mpc.hi_u, N), -np.tile(mpc.lo_u, N)]
    if nc:
        G = sp.hstack([sp.csc_matrix((N * nc, N * m)), sp.kron(sp.eye(N), mpc.Hx), -sp.eye(N * nc)])
        for sign, bound in ((1.0, mpc.hi_x), (-1.0, -mpc.lo_x)):
            keep = np.flatnonzero(np.isfinite(np.tile(bound, N)))
            rows.append(sign * G.tocsr()[keep])
            b.append(np.tile(bound, N)[keep])
    Acon = sp.vstack(rows, format="csc")
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = tol
    cones = [clarabel.ZeroConeT(N * nx), clarabel.NonnegativeConeT(Acon.shape[0] - N * nx)]
    res = clarabel.DefaultSolver(sp.triu(H, format="csc"), np.zeros(nv), Acon, np.concatenate(b), cones,
                                 settings).solve()  # fmt: skip
    status = str(res.status)
    if "Solved" not in status:
        raise GainlinkError(f"Clarabel did not solve the MPC's QP: {status}")
    return _solution(mpc, x0, np.array(res.x), H, status)


def _solution(mpc: Mpc, x0: np.ndarray, v: np.ndarray, H: sp.csc_matrix, status: str) -> QpSolution:
    N, m, nx = mpc.horizon, mpc.B.shape[1], mpc.nx
    u = v[: N * m].reshape(N, m)
    x = np.vstack([x0, v[N * m : N * m + N * nx].reshape(N, nx)])
    cost = 0.5 * float(v @ (H @ v)) + 0.5 * float(x0 @ mpc.Q @ x0)
    return QpSolution(u=u, x=x, cost=cost, status=status)
