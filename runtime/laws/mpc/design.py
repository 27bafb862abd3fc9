"""The MPC law's design step: the observer-based pipeline (the LQ gain the MPC reduces to, the observer, the
integrators and their anti-windup), then the ``mpc`` block (:mod:`gainlink.laws.mpc.block`): the terminal cost as the
DARE solution of the same weights, the penalties by their default rules, the per-stage gains, the boxes.

Refused in one line (exit 2): a terminal cost that is not positive definite (the weights leave a mode unseen), a box
on an output of a plant with feedthrough, and what :func:`gainlink.laws.mpc.spec.check_mpc_spec` refuses at parse time.
"""

from __future__ import annotations

import numpy as np

from ...errors import DesignError
from ...shipping.artifact import matrix_to_json
from ...spec import PlantSpec
from .block import augmented_model, box_rows, stage_cache
from .spec import weights_default


def _terminal_cost(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray, K: np.ndarray) -> np.ndarray:
    """The DARE solution of (A, B, Q, R) (python-control, SLICOT), positive definite and giving the design's own
    gain, else DesignError."""
    import control

    P, _, G = control.dare(A, B, Q, R)
    P = (np.asarray(P) + np.asarray(P).T) / 2
    low = float(np.min(np.linalg.eigvalsh(P)))
    if low <= 1e-12 * max(1.0, float(np.max(np.abs(P)))):
        raise DesignError(
            f"the MPC's terminal cost (the DARE solution of Q and R) is not positive definite (smallest eigenvalue "
            f"{low:.3g}): give every state and integrator a weight the cost can see"
        )
    if np.max(np.abs(np.asarray(G) - K)) > 1e-6 * max(1.0, float(np.max(np.abs(K)))):
        raise DesignError("the DARE solution of the MPC's weights does not give the design's LQ gain")
    return P


def _boxes(spec: PlantSpec) -> list[dict]:
    """The soft boxes as the artifact records them (absolute; None for an infinite side)."""
    side = lambda v: None if not np.isfinite(v) else float(v)  # noqa: E731
    return [{"name": b.name, "kind": b.kind, "index": b.index, "lo": side(b.lo), "hi": side(b.hi)}
            for b in spec.mpc.boxes]  # fmt: skip


def mpc_block(spec: PlantSpec, data: dict) -> dict:
    """The ``mpc`` block for the observer-based law ``data`` (unsealed) of ``spec``."""
    mpc = spec.mpc
    Ad, Bd, Cd, Dd = (np.array(data[k], dtype=float) for k in ("Ad", "Bd", "Cd", "Dd"))
    n, q = Ad.shape[0], spec.q
    Ci = np.array(data["Ci"], dtype=float) if q else np.zeros((0, Cd.shape[0]))
    A, B = augmented_model(Ad, Bd, Cd, Dd, Ci, spec.Ts)
    rec = data["design"]["controller"]
    Q, R = np.array(rec["Q"], dtype=float), np.array(rec["R"], dtype=float)
    K = np.hstack(
        [np.array(data["K"], dtype=float), np.array(data["Ki"], dtype=float) if q else np.zeros((B.shape[1], 0))]
    )
    P = _terminal_cost(A, B, Q, R, K)
    boxes = _boxes(spec)
    if Dd.any() and any(b["kind"] == "output" for b in boxes):
        raise DesignError("an MPC box on an output needs a plant without feedthrough (Dd = 0): box the states instead")
    x_op = np.array(data["x_op"]) if "x_op" in data else None
    y_op = np.array(data.get("y_op", np.zeros(Cd.shape[0])))
    Hx, _, _ = box_rows(boxes, n=n, q=q, Cd=Cd, x_op=x_op, y_op=y_op)
    rho, rho_state, box_weight = weights_default(Q, R, mpc)
    Kc, C1 = stage_cache(A, B, Q, R, P, Hx, mpc.horizon, rho, rho_state)
    return {
        "horizon": mpc.horizon, "max_iter": mpc.max_iter, "tol": mpc.tol, "rho": rho, "rho_state": rho_state,
        "box_weight": box_weight, "A": matrix_to_json(A), "B": matrix_to_json(B), "Q": matrix_to_json(Q),
        "R": matrix_to_json(R), "P": matrix_to_json(P), "K": [matrix_to_json(k) for k in Kc],
        "C1": [matrix_to_json(c) for c in C1], "boxes": boxes,
    }  # fmt: skip


def mpc_check(data: dict, spec: PlantSpec, warnings: list[str]) -> dict:
    """The law's implementation step (:data:`gainlink.synthesis.pipeline.ImplementationCheck`): the ``mpc`` block
    into ``data``. The closed-loop float32 fidelity of the observer-based law does not apply (the MPC's command is
    another function); the C's float32 is checked against its bit-exact model and the float64 algorithm instead."""
    data["mpc"] = mpc_block(spec, data)
    return {"float32": None}
