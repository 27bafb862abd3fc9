"""Realisations of the estimate's coordinates: ``xh' = T xh``, applied to the artifact.

The control law is the same in any coordinates of the estimate, so a change ``xh' = T xh`` gives the
same input/output behaviour in exact arithmetic, but not the same float32 rounding: the C folds the
observer into ``F = Ad - L Cd`` and accumulates ``F xh + G u + L y`` in float32, where large terms that
cancel (a large ``L`` against a large ``L Cd xh``, a state component far larger than another that
it drives) lose the small result's precision. Realisations:

``as_designed``
    The coordinates of the plant as specified (``T = I``).
``balanced``
    The internally balanced realisation of the recursion the C runs, from ``(u, y)`` to ``v`` through
    the estimate: ``(F, [G L], K)`` in the predictor form, ``(Ad (I - M Cd), [Bd, Ad M], K (I - M Cd))``
    in the current form. ``F`` is the observer's error dynamics, always stable, so both Gramians exist
    even when the compensator itself is unstable. In balanced coordinates every state component is
    equally reachable from the inputs and equally visible in the command (Hankel singular values on the
    diagonal of both Gramians): no component is tiny next to another, which is what keeps the
    float32 sums from cancelling; it is the classical minimum-roundoff-noise choice for state-space
    filters (Mullis & Roberts 1976; Gevers & Li 1993). Hankel singular values below
    ``1e-10`` of the largest (a nearly unreachable or invisible direction) are floored there, so ``T``
    stays invertible.
``schur``
    An orthogonal ``T`` (``F = Q S Q'``, real Schur form, ``T = Q'``): ``F`` becomes upper quasi-triangular
    with one observer pole per diagonal block, and norms are unchanged (``cond(T) = 1``). Offered because
    it is the textbook well-conditioned form, but measured it is not a cure: the rotation mixes state
    components of very different size, so on the flexible-structure test case (a rigid body with a
    stiff, lightly damped appendage, sampled at 5 kHz) it did no better than ``as_designed`` and on
    several others it was worse, while ``balanced`` was 10-300 times better. ``balanced`` is the
    recommended remedy; ``schur`` is there for comparison.

Diagonal scaling alone would change nothing: float32 rounding is relative, so rescaling a state
rescales its errors with it. What a realisation can remove is cancellation between components.

The artifact records ``realization = {"kind", "T", "design": {Ad, Bd, Cd, K, L[, M], xh0}}``: the matrices
in the design's own coordinates, from which every gain is recomputed (the top-level ``Ad Bd Cd K L M xh0``
are ``T Ad T^-1``, ``T Bd``, ``Cd T^-1``, ``K T^-1``, ``T L``, ``T M``, ``T xh0``; ``Dd``, ``Ci``, ``Ki``,
``Kaw``, limits and the operating point do not depend on the coordinates). Both the float64 reference
and the C read the top-level matrices, so they run the same realisation.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from ..errors import SpecError
from ..shipping.artifact import matrix_to_json, vector_to_json

REALIZATIONS = ("as_designed", "balanced", "schur")
HSV_FLOOR = 1e-10


def observer_recursion(*, Ad, Bd, Cd, Dd, K, L, M, form: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(F, B, C)`` of the estimate's recursion as the C runs it: ``xh+ = F xh + B [u; y]``, ``v = -C xh + ...``."""
    n = Ad.shape[0]
    if form == "current":
        F = Ad @ (np.eye(n) - M @ Cd)
        return F, np.hstack([Bd, Ad @ M]), K @ (np.eye(n) - M @ Cd)
    return Ad - L @ Cd, np.hstack([Bd - L @ Dd, L]), K


def transformation(kind: str, *, Ad, Bd, Cd, Dd, K, L, M, form: str) -> np.ndarray:
    """The matrix ``T`` of ``xh' = T xh`` for realisation ``kind`` (see the module docstring)."""
    n = Ad.shape[0]
    if kind == "as_designed":
        return np.eye(n)
    F, B, C = observer_recursion(Ad=Ad, Bd=Bd, Cd=Cd, Dd=Dd, K=K, L=L, M=M, form=form)
    if kind == "schur":
        _, Q = scipy.linalg.schur(F, output="real")
        return Q.T
    if kind == "balanced":
        return _balancing(F, B, C)
    raise SpecError(f"implementation.realization must be one of {', '.join(REALIZATIONS)}, not {kind!r}")


def _sqrt_factor(W: np.ndarray) -> np.ndarray:
    """A factor ``R`` with ``W = R R'`` of a symmetric positive semi-definite Gramian."""
    w, V = np.linalg.eigh((W + W.T) / 2)
    return V * np.sqrt(np.maximum(w, 0.0))


def _balancing(F: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Square-root balancing of a stable ``(F, B, C)``: ``T Wc T' = T^-T Wo T^-1 = diag(hsv)``."""
    import control

    Wc = control.dlyap(F, B @ B.T)  # SLICOT's Bartels-Stewart: F W F' - W + B B' = 0
    Wo = control.dlyap(F.T, C.T @ C)
    Rc, Ro = _sqrt_factor(Wc), _sqrt_factor(Wo)
    U, s, _ = np.linalg.svd(Ro.T @ Rc)
    s = np.maximum(s, HSV_FLOOR * s[0])
    return (U / np.sqrt(s)).T @ Ro.T


def apply(data: dict, *, kind: str, T: np.ndarray) -> dict:
    """The artifact dict with the estimate in the coordinates ``xh' = T xh``, the design's matrices recorded.

    ``data`` holds the design coordinates (as :func:`gainlink.design.design` builds it before sealing);
    the result is not sealed.
    """
    out = dict(data)
    n = int(data["n"])
    Ti = np.linalg.inv(T)
    Ad, Bd, Cd = (np.array(data[k], dtype=float) for k in ("Ad", "Bd", "Cd"))
    K, L = np.array(data["K"], dtype=float), np.array(data["L"], dtype=float)
    xh0 = np.array(data.get("xh0", np.zeros(n)), dtype=float)
    design = {k: data[k] for k in ("Ad", "Bd", "Cd", "K", "L")}
    design["xh0"] = vector_to_json(xh0)
    out.update(
        Ad=matrix_to_json(T @ Ad @ Ti),
        Bd=matrix_to_json(T @ Bd),
        Cd=matrix_to_json(Cd @ Ti),
        K=matrix_to_json(K @ Ti),
        L=matrix_to_json(T @ L),
    )
    if "M" in data:
        design["M"] = data["M"]
        out["M"] = matrix_to_json(T @ np.array(data["M"], dtype=float))
    if "xh0" in data or np.any(xh0):
        out["xh0"] = vector_to_json(T @ xh0)
    out["realization"] = {"kind": kind, "T": matrix_to_json(T), "design": design}
    return out
