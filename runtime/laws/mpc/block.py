"""The ``mpc`` block of an artifact: the constrained law's prediction model, weights, boxes, solver settings and the
per-stage gains its Riccati passes use (docs/design.md, "MPC (the fourth law)").

The block sits beside an observer-based law's matrices (schema 1: ``Ad Bd Cd Dd K L``, the integrators, the limits),
whose observer and integrators the MPC law keeps; only the command changes: the first move of the QP over the
horizon instead of ``-K xh - Ki z``. What it holds (``nx = n + q``: the estimate and the integrators):

- ``horizon`` N, ``max_iter`` (the cap), ``tol``, ``rho`` (input slacks), ``rho_state`` (box slacks),
  ``box_weight`` (the soft boxes' quadratic penalty);
- ``A`` (nx x nx), ``B`` (nx x m): the design's augmented model (integrators ``z+ = z - Ts Ci (Cd x + Dd u)``, the
  LQI design's), ``Q`` (nx x nx), ``R`` (m x m) its weights and ``P`` the DARE solution of them (terminal cost);
- ``boxes``: the soft boxes as the spec gave them (absolute, ``null`` for an infinite side), as rows ``Hx`` of the
  augmented state (a unit row for a state, a row of ``Cd`` for an output);
- ``K`` (N x m x nx) and ``C1`` (N x m x m): the per-stage gains of the penalised problem, stage ``k`` from
  ``P_{k+1}`` with ``P_N = P + rho_state H'H`` and ``P_k = Q + rho_state H'H + A' P_{k+1} (A - B K_k)``:
  ``C1_k = (R + rho I + B' P_{k+1} B)^-1``, ``K_k = C1_k B' P_{k+1} A``.

:func:`stage_cache` computes the gains; loading an artifact recomputes them (and the model from the observer-based
law's matrices) and refuses one whose numbers differ: an edited block cannot run another law.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import ArtifactError

#: A box bound without its side (JSON has no infinity).
_BIG = math.inf


@dataclass(frozen=True)
class Mpc:
    """The loaded ``mpc`` block (module docstring) with the derived deviation boxes.

    ``lo_u``, ``hi_u`` (m) are the input box about the operating point (``u_min - u_op``, ``u_max - u_op``);
    ``Hx`` (nc x nx) the box rows, ``lo_x``, ``hi_x`` (nc) their bounds as deviations (``-inf``/``inf`` for a side
    without one); ``scale_u`` (m), ``scale_x`` (nc) each constrained signal's scale (a box's width; one-sided, the
    magnitude of its finite bound, at least 1e-6) to which ``tol`` is relative.
    """

    horizon: int
    max_iter: int
    tol: float
    rho: float
    rho_state: float
    box_weight: float
    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    K: np.ndarray
    C1: np.ndarray
    boxes: tuple[dict, ...]
    Hx: np.ndarray
    lo_x: np.ndarray
    hi_x: np.ndarray
    lo_u: np.ndarray
    hi_u: np.ndarray

    @property
    def nx(self) -> int:
        """The prediction model's state: the estimate and the integrators."""
        return self.A.shape[0]

    @property
    def nc(self) -> int:
        """Soft box rows."""
        return self.Hx.shape[0]

    @property
    def scale_u(self) -> np.ndarray:
        """Each input's scale: its box's width."""
        return self.hi_u - self.lo_u

    @property
    def scale_x(self) -> np.ndarray:
        """Each box row's scale: its width, or the magnitude of its one finite bound (at least 1e-6)."""
        return np.array([_scale(lo, hi) for lo, hi in zip(self.lo_x, self.hi_x, strict=True)])

    @property
    def kappa(self) -> float:
        """The soft boxes' proximal factor ``w / (rho_state + w)``: a slack outside its box moves that fraction of
        the way back to it."""
        return self.box_weight / (self.rho_state + self.box_weight)

    @property
    def eps(self) -> dict[str, np.ndarray]:
        """The stopping thresholds, absolute, per input (``pu``, ``du``) and box row (``px``, ``dx``): primal
        ``|v - z| <= tol scale``; dual ``rho |z - z_prev| <= tol rho scale f`` with ``f = r / (r + rho)``, ``r`` the
        smallest eigenvalue of R. Why ``f``: with no box active an iteration is a proximal step on the moves, whose
        error contracts by at most ``rho / (r + rho)`` (the QP's curvature in the moves is at least R's), so a move
        of the slacks of ``delta`` leaves the moves within ``delta (r + rho) / r`` of the optimum: ``f`` makes that
        ``tol scale``. A test on ``rho |delta|`` against ``tol rho scale`` alone stopped the pendulum 2.3 tolerances
        from its optimum (``0.09`` N against ``0.04``)."""
        r = float(np.min(np.linalg.eigvalsh(self.R)))
        f = r / (r + self.rho)
        return {"pu": self.tol * self.scale_u, "du": self.tol * self.rho * f * self.scale_u,
                "px": self.tol * self.scale_x, "dx": self.tol * self.rho_state * f * self.scale_x}  # fmt: skip


def _scale(lo: float, hi: float) -> float:
    if math.isfinite(lo) and math.isfinite(hi):
        return hi - lo
    return max(abs(lo) if math.isfinite(lo) else abs(hi), 1e-6)


def augmented_model(Ad, Bd, Cd, Dd, Ci, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The LQI design's augmented model: ``x+ = Ad x + Bd u``, ``z+ = z - Ts Ci (Cd x + Dd u)`` (the reference
    enters through the integrators' own state, as in the LQ law's design)."""
    n, q = Ad.shape[0], Ci.shape[0]
    A = np.block([[Ad, np.zeros((n, q))], [-Ts * Ci @ Cd, np.eye(q)]])
    B = np.vstack([Bd, -Ts * Ci @ Dd])
    return A, B


def stage_cache(A, B, Q, R, P, Hx, horizon: int, rho: float, rho_state: float) -> tuple[np.ndarray, np.ndarray]:
    """``K`` (N, m, nx) and ``C1`` (N, m, m), stage by stage from the terminal cost (module docstring).

    The penalties go exactly on the variables that carry a slack: every input (``rho I``), the box rows of x1..xN
    (``rho_state H'H``), x_N included; x0 is the estimate and carries none."""
    m = B.shape[1]
    Qr = Q + rho_state * Hx.T @ Hx
    Rr = R + rho * np.eye(m)
    Pk = P + rho_state * Hx.T @ Hx
    K = np.zeros((horizon, m, A.shape[0]))
    C1 = np.zeros((horizon, m, m))
    for k in range(horizon - 1, -1, -1):
        C1[k] = np.linalg.inv(Rr + B.T @ Pk @ B)
        C1[k] = (C1[k] + C1[k].T) / 2
        K[k] = C1[k] @ (B.T @ Pk @ A)
        Pk = Qr + A.T @ Pk @ (A - B @ K[k])
        Pk = (Pk + Pk.T) / 2
    return K, C1


def box_rows(boxes, *, n: int, q: int, Cd: np.ndarray, x_op, y_op) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each box as a row of the augmented state and its bounds as deviations (``inf`` for a missing side)."""
    rows, lo, hi = [], [], []
    for b in boxes:
        if b["kind"] == "state":
            row, at = np.eye(n + q)[b["index"]], 0.0 if x_op is None else float(x_op[b["index"]])
        else:
            row, at = np.concatenate([Cd[b["index"]], np.zeros(q)]), float(y_op[b["index"]])
        rows.append(row)
        lo.append(-_BIG if b["lo"] is None else b["lo"] - at)
        hi.append(_BIG if b["hi"] is None else b["hi"] - at)
    return np.array(rows).reshape(len(rows), n + q), np.array(lo), np.array(hi)


def _array(block: dict, key: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        a = np.array(block[key], dtype=float)
    except (KeyError, ValueError, TypeError):
        raise ArtifactError(f"artifact mpc.{key} is missing or not numeric") from None
    if a.shape != shape:
        raise ArtifactError(f"artifact mpc.{key} has shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise ArtifactError(f"artifact mpc.{key} holds a non-finite entry")
    return a


def load_mpc(data: dict, *, Ad, Bd, Cd, Dd, Ci, Ts, u_min, u_max, u_op, x_op, y_op) -> Mpc:
    """The ``mpc`` block of ``data`` checked against the law's matrices (module docstring)."""
    b = data["mpc"]
    n, m = Bd.shape
    q = Ci.shape[0]
    N, nx = int(b["horizon"]), n + q
    A, B = augmented_model(Ad, Bd, Cd, Dd, Ci, Ts)
    Q, R, P = _array(b, "Q", (nx, nx)), _array(b, "R", (m, m)), _array(b, "P", (nx, nx))
    K, C1 = _array(b, "K", (N, m, nx)), _array(b, "C1", (N, m, m))
    for key, want in (("A", A), ("B", B)):
        got = _array(b, key, want.shape)
        if np.max(np.abs(got - want), initial=0.0) > 1e-12 * max(1.0, np.max(np.abs(want))):
            raise ArtifactError(f"artifact mpc.{key} is not the augmented model of Ad, Bd, Cd, Dd, Ci and Ts")
    if np.min(np.linalg.eigvalsh((P + P.T) / 2)) <= 0.0:
        raise ArtifactError("artifact mpc.P (the terminal cost) is not positive definite")
    boxes = tuple(b["boxes"])
    Hx, lo_x, hi_x = box_rows(boxes, n=n, q=q, Cd=Cd, x_op=x_op, y_op=y_op)
    if Dd.any() and any(x["kind"] == "output" for x in boxes):
        raise ArtifactError("artifact mpc.boxes box an output of a plant with feedthrough (Dd != 0)")
    K_, C1_ = stage_cache(A, B, Q, R, P, Hx, N, float(b["rho"]), float(b["rho_state"]))
    for key, got, want in (("K", K, K_), ("C1", C1, C1_)):
        if np.max(np.abs(got - want)) > 1e-9 * max(1.0, np.max(np.abs(want))):
            raise ArtifactError(f"artifact mpc.{key} is not the per-stage gain of its weights, model and penalties")
    return Mpc(horizon=N, max_iter=int(b["max_iter"]), tol=float(b["tol"]), rho=float(b["rho"]),
               rho_state=float(b["rho_state"]), box_weight=float(b["box_weight"]), A=A, B=B, Q=Q, R=R, P=P, K=K,
               C1=C1, boxes=boxes, Hx=Hx, lo_x=lo_x, hi_x=hi_x, lo_u=u_min - u_op, hi_u=u_max - u_op)  # fmt: skip
