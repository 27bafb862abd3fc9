"""Families of small LMIs in the unknown symmetric matrices ``P_0 .. P_K``, solved by Clarabel (SCS as the
fallback) through their own conic interfaces.

Each constraint reads ``sum_k (a_k P_k - b_k V' P_k V) - I >= 0`` (``a``, ``b``: weights per node, ``V`` a
vertex matrix) or is a bound ``I <= P_k <= t I``; the objective is the smallest ``t``. The constraints are
assembled as one sparse matrix in the solvers' standard form ``A x + s = b, s in K`` with one small PSD cone per
constraint: a modelling layer such as cvxpy canonicalises each constraint on its own, which took 22 s for the
890 2x2 LMIs of one bisection step of a rate certificate here, against well under a second this way.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import DesignError

SQRT2 = np.sqrt(2.0)


def _upper_index(N: int) -> list[tuple[int, int]]:
    """The (row, col) of each svec entry: the upper triangle column by column (Clarabel's order)."""
    return [(i, j) for j in range(N) for i in range(j + 1)]


def svec(X: np.ndarray) -> np.ndarray:
    """Upper triangle column by column, off-diagonal entries times sqrt(2) (so <svec X, svec Y> = tr(X Y))."""
    return np.array([X[i, j] * (1.0 if i == j else SQRT2) for i, j in _upper_index(X.shape[0])])


def smat(v: np.ndarray, N: int) -> np.ndarray:
    """The inverse of :func:`svec`."""
    X = np.zeros((N, N))
    for value, (i, j) in zip(v, _upper_index(N)):
        X[i, j] = X[j, i] = value if i == j else value / SQRT2
    return X


def congruence(V: np.ndarray) -> np.ndarray:
    """The matrix of ``svec(P) -> svec(V' P V)``."""
    N = V.shape[0]
    basis = np.eye(N * (N + 1) // 2)
    return np.array([svec(V.T @ smat(e, N) @ V) for e in basis]).T


@dataclass
class LmiFamily:
    """Constraints on ``nodes`` unknown N x N symmetric matrices, added with :meth:`decrease`; solved by
    :meth:`solve`."""

    N: int
    nodes: int
    rows: list = field(default_factory=list)  # (nb x (nodes nb + 1)) blocks, one per PSD cone
    rhs: list = field(default_factory=list)
    _congruences: dict = field(default_factory=dict)

    @property
    def nb(self) -> int:
        """Entries of one svec."""
        return self.N * (self.N + 1) // 2

    def decrease(self, a: np.ndarray, b: np.ndarray, V: np.ndarray) -> None:
        """``sum_k a_k P_k - sum_k b_k V' P_k V - I >= 0``."""
        T = self._congruences.setdefault(id(V), (V, congruence(V)))[1]
        block = np.zeros((self.nb, self.nodes * self.nb + 1))
        for k in range(self.nodes):
            if a[k] or b[k]:
                block[:, k * self.nb : (k + 1) * self.nb] = a[k] * np.eye(self.nb) - b[k] * T
        self._add(block, svec(np.eye(self.N)))

    def _bounds(self) -> None:
        """``P_k - I >= 0`` and ``t I - P_k >= 0`` for every node."""
        I = svec(np.eye(self.N))
        for k in range(self.nodes):
            lower = np.zeros((self.nb, self.nodes * self.nb + 1))
            lower[:, k * self.nb : (k + 1) * self.nb] = np.eye(self.nb)
            self._add(lower, I)
            upper = -lower
            upper[:, -1] = I
            self._add(upper, np.zeros(self.nb))

    def _add(self, block: np.ndarray, offset: np.ndarray) -> None:
        # the cone holds s = block x - offset; in standard form A x + s = b: A = -block, b = -offset
        self.rows.append(-block)
        self.rhs.append(-offset)

    def solve(self, proves: Callable[[list[np.ndarray]], bool]) -> tuple[list[np.ndarray] | None, str]:
        """``(P_0 .. P_K, solver)``: the matrices, or None when infeasible; DesignError when both solvers fail.

        ``proves(Ps)`` is the caller's float64 re-check of a solution. A solver that stops short of its tolerances
        (Clarabel's InsufficientProgress or MaxIterations, SCS's inaccurate) often holds a valid certificate on an
        ill-conditioned problem (a slow loop needs a P with a condition number near 1e7): its candidate is kept
        when ``proves`` accepts it, and the next solver is tried when not. Only when no solver answers and no
        candidate is proved is it a failure."""
        self._bounds()
        A = sp.csc_matrix(np.vstack(self.rows))
        b = np.concatenate(self.rhs)
        c = np.zeros(A.shape[1])
        c[-1] = 1.0
        errors = []
        for name, run in (("Clarabel", _clarabel), ("SCS", _scs)):
            try:
                status, x = run(A, b, c, cones=len(self.rows), N=self.N)
            except Exception as exc:  # the solvers raise assorted exception types
                errors.append(f"{name}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
                continue
            if status == "infeasible":
                return None, name
            Ps = self._matrices(x)
            if status == "solved":
                return Ps, name
            if Ps is not None and proves(Ps):
                return Ps, f"{name} ({status}; its candidate re-checked)"
            errors.append(f"{name}: {status}")
        raise DesignError(f"the LMI solver failed on the scheduled loop's Lyapunov problem ({'; '.join(errors)})")

    def _matrices(self, x: np.ndarray) -> list[np.ndarray] | None:
        """``P_0 .. P_K`` from a solver's x, None when it holds none (or not finite numbers)."""
        if x.size < self.nodes * self.nb or not np.all(np.isfinite(x)):
            return None
        return [smat(x[k * self.nb : (k + 1) * self.nb], self.N) for k in range(self.nodes)]


def _clarabel(A, b, c, *, cones: int, N: int) -> tuple[str, np.ndarray]:
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    solver = clarabel.DefaultSolver(sp.csc_matrix((A.shape[1], A.shape[1])), c, A, b,
                                    [clarabel.PSDTriangleConeT(N)] * cones, settings)  # fmt: skip
    sol = solver.solve()
    status = str(sol.status)
    if status in ("Solved", "AlmostSolved"):
        return "solved", np.array(sol.x)
    if status in ("PrimalInfeasible", "AlmostPrimalInfeasible", "DualInfeasible", "AlmostDualInfeasible"):
        return "infeasible", np.zeros(0)
    return status, np.array(sol.x)  # stopped short: the candidate, for the caller's re-check


def _scs(A, b, c, *, cones: int, N: int) -> tuple[str, np.ndarray]:
    """SCS wants the lower triangle column by column: the same entries in another order."""
    import scs

    order = _scs_order(N)
    perm = np.concatenate([k * len(order) + order for k in range(cones)])
    data = {"A": sp.csc_matrix(A[perm]), "b": b[perm], "c": c}
    sol = scs.SCS(data, {"s": [N] * cones}, verbose=False, eps_abs=1e-9, eps_rel=1e-9).solve()
    status = sol["info"]["status"]
    if status == "solved":
        return "solved", np.array(sol["x"])
    if "infeasible" in status:
        return "infeasible", np.zeros(0)
    return status, np.array(sol["x"])  # inaccurate: the candidate, for the caller's re-check


def _scs_order(N: int) -> np.ndarray:
    """Positions in Clarabel's svec of SCS's entries (lower triangle column by column = upper row by row)."""
    upper = {ij: k for k, ij in enumerate(_upper_index(N))}
    return np.array([upper[(j, i)] for j in range(N) for i in range(j, N)])
