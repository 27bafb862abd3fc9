"""Families of small LMIs in the unknown symmetric matrices ``P_0 .. P_K``, solved by Clarabel (SCS as the
fallback) through their own conic interfaces.

Each constraint reads ``sum_k (a_k P_k - b_k V' P_k V) >= mu I`` (``a``, ``b``: weights per node, ``V`` a vertex
matrix), the nodes are bounded, ``I <= P_k <= cap I``, and the objective is the largest ``mu``: a problem that
always has a solution, whose ``mu`` says how far the family is from holding (``mu > 0``: it holds) and whose dual
says which constraints bind (their share of the dual, :attr:`LmiSolution.weights`, sums to one). The caller's
coordinates should make a certificate's ``P`` well conditioned (``cap`` bounds its condition number).

The constraints are assembled as one sparse matrix in the solvers' standard form ``A x + s = b, s in K`` with one
small PSD cone per constraint: a modelling layer such as cvxpy canonicalises each constraint on its own, which took
22 s for the 890 2x2 LMIs of one bisection step of a rate certificate here, against well under a second this way.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import DesignError

SQRT2 = np.sqrt(2.0)
#: Bound on the condition number of every ``P`` (in the caller's well-scaled coordinates).
CAP = 1e4
#: SCS, the fallback, stops here: a first-order method is slow on these problems (minutes for 700 cones).
SCS_MAX_ITERS = 20000


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


def _svec_maps(N: int) -> tuple[np.ndarray, np.ndarray]:
    """``(S, U)``: ``svec(X) = S vec(X)`` and ``vec(X) = U svec(X)`` for symmetric X (vec row by row)."""
    idx = _upper_index(N)
    S, U = np.zeros((len(idx), N * N)), np.zeros((N * N, len(idx)))
    for k, (i, j) in enumerate(idx):
        S[k, i * N + j] = 1.0 if i == j else SQRT2
        U[i * N + j, k] = U[j * N + i, k] = 1.0 if i == j else 1.0 / SQRT2
    return S, U


def congruence(V: np.ndarray) -> np.ndarray:
    """The matrix of ``svec(P) -> svec(V' P V)``: ``vec(V' P V) = (V' kron V') vec(P)``."""
    S, U = _svec_maps(V.shape[0])
    return S @ np.kron(V.T, V.T) @ U


@dataclass(frozen=True)
class LmiSolution:
    """The solver's ``P_0 .. P_K`` (a candidate: the caller re-checks it), its ``mu``, each constraint's share of
    the dual (in the order added), and which solver answered how."""

    P: list[np.ndarray]
    mu: float
    weights: np.ndarray
    solver: str


@dataclass
class LmiFamily:
    """Constraints on ``nodes`` unknown N x N symmetric matrices, added with :meth:`decrease`; solved by
    :meth:`solve`."""

    N: int
    nodes: int
    cap: float = CAP
    _rows: list = field(default_factory=list)
    _cols: list = field(default_factory=list)
    _vals: list = field(default_factory=list)
    _count: int = 0
    _congruences: dict = field(default_factory=dict)

    @property
    def nb(self) -> int:
        """Entries of one svec."""
        return self.N * (self.N + 1) // 2

    @property
    def size(self) -> int:
        """Constraints added so far."""
        return self._count

    def decrease(self, a: np.ndarray, b: np.ndarray, V: np.ndarray, T: np.ndarray | None = None) -> None:
        """``sum_k a_k P_k - sum_k b_k V' P_k V >= mu I``; ``T``: ``congruence(V)`` when the caller keeps it."""
        nb, I = self.nb, np.eye(self.nb)
        if T is None:
            T = self._congruences.setdefault(id(V), (V, congruence(V)))[1]
        for k in np.flatnonzero((a != 0) | (b != 0)):
            self._block(self._count, k, a[k] * I - b[k] * T)
        mu = np.zeros((nb, 1))
        mu[:, 0] = -svec(np.eye(self.N))
        self._block(self._count, self.nodes, mu, width=1)
        self._count += 1

    def _block(self, cone: int, node: int, M: np.ndarray, width: int | None = None) -> None:
        """``M`` (the cone's rows of G in ``s = G x``) at node ``node``'s columns (the last column is mu)."""
        r, c = np.nonzero(M)
        self._rows.append(cone * self.nb + r)
        self._cols.append(node * self.nb + c)
        self._vals.append(M[r, c])

    def _standard_form(self) -> tuple[sp.csc_matrix, np.ndarray, np.ndarray, int]:
        """``A, b, c`` and the number of cones: the decrease cones (``s = G x``: ``A = -G``, ``b = 0``), then per
        node ``P - I >= 0`` (``A = -E_k``, ``b = -svec I``) and ``cap I - P >= 0`` (``A = E_k``, ``b = cap svec I``)."""
        nb, K = self.nb, self.nodes
        rows, cols = list(self._rows), list(self._cols)
        vals = [-v for v in self._vals]
        b = [np.zeros(self._count * nb)]
        I = svec(np.eye(self.N))
        base = self._count * nb
        for k in range(K):
            for sign, offset in ((-1.0, -I), (1.0, self.cap * I)):
                rows.append(base + np.arange(nb))
                cols.append(k * nb + np.arange(nb))
                vals.append(np.full(nb, sign))
                b.append(offset)
                base += nb
        A = sp.csc_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(base, K * nb + 1)
        )
        c = np.zeros(K * nb + 1)
        c[-1] = -1.0  # maximise mu
        return A, np.concatenate(b), c, self._count + 2 * K

    def solve(self) -> LmiSolution:
        """The candidate of Clarabel (SCS when Clarabel fails outright); DesignError when neither answers."""
        A, b, c, cones = self._standard_form()
        errors = []
        for name, run in (("Clarabel", _clarabel), ("SCS", _scs)):
            try:
                status, x, z = run(A, b, c, cones=cones, N=self.N)
            except Exception as exc:  # the solvers raise assorted exception types
                errors.append(f"{name}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
                continue
            if x.size == A.shape[1] and np.all(np.isfinite(x)):
                return self._solution(x, z, f"{name} ({status})")
            errors.append(f"{name}: {status}")
        raise DesignError(f"the LMI solver failed on the scheduled loop's Lyapunov problem ({'; '.join(errors)})")

    def _solution(self, x: np.ndarray, z: np.ndarray, solver: str) -> LmiSolution:
        nb = self.nb
        Ps = [smat(x[k * nb : (k + 1) * nb], self.N) for k in range(self.nodes)]
        diag = np.array([1.0 if i == j else 0.0 for i, j in _upper_index(self.N)])
        if z.size >= self._count * nb and np.all(np.isfinite(z)):
            traces = np.abs(z[: self._count * nb].reshape(self._count, nb) @ diag)
        else:
            traces = np.ones(self._count)
        total = float(traces.sum())
        weights = traces / total if total > 0 else np.full(self._count, 1.0 / max(self._count, 1))
        return LmiSolution(P=Ps, mu=float(x[-1]), weights=weights, solver=solver)


def _clarabel(A, b, c, *, cones: int, N: int) -> tuple[str, np.ndarray, np.ndarray]:
    """One thread, no iterative refinement: the candidate is re-checked anyway, and this halves the time."""
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_threads = 1
    settings.iterative_refinement_enable = False
    settings.direct_solve_method = "qdldl"
    solver = clarabel.DefaultSolver(sp.csc_matrix((A.shape[1], A.shape[1])), c, A, b,
                                    [clarabel.PSDTriangleConeT(N)] * cones, settings)  # fmt: skip
    sol = solver.solve()
    return str(sol.status), np.array(sol.x), np.array(sol.z)


def _scs(A, b, c, *, cones: int, N: int) -> tuple[str, np.ndarray, np.ndarray]:
    """SCS wants the lower triangle column by column: the same entries in another order."""
    import scs

    order = _scs_order(N)
    perm = np.concatenate([k * len(order) + order for k in range(cones)])
    data = {"A": sp.csc_matrix(A[perm]), "b": b[perm], "c": c}
    sol = scs.SCS(data, {"s": [N] * cones}, verbose=False, eps_abs=1e-7, eps_rel=1e-7,
                  max_iters=SCS_MAX_ITERS).solve()  # fmt: skip
    z = np.empty_like(sol["y"])
    z[perm] = sol["y"]
    return sol["info"]["status"], np.array(sol["x"]), z


def _scs_order(N: int) -> np.ndarray:
    """Positions in Clarabel's svec of SCS's entries (lower triangle column by column = upper row by row)."""
    upper = {ij: k for k, ij in enumerate(_upper_index(N))}
    return np.array([upper[(j, i)] for j in range(N) for i in range(j, N)])
