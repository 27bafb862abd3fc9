"""The observer gain: a Kalman filter (DARE), Luenberger pole placement, or the user's own ``L`` (or ``M``), in
predictor or current form (``L = Ad M``)."""

from __future__ import annotations

import numpy as np

from ..errors import DesignError, SpecError
from ..shipping.artifact import matrix_to_json
from ..spec import PlantSpec
from .analysis import complex_pairs
from .controller import check_psd
from .discretize import Discretised


def observer_gain(spec: PlantSpec, d: Discretised) -> tuple[np.ndarray, np.ndarray | None, dict]:
    """``(L, M, record)``: ``M`` only in the current form; ``record`` is the artifact's design record."""
    obs = spec.observer
    if obs.form == "current" and np.any(d.D != 0):
        raise SpecError(
            "observer.form 'current' requires a plant without feedthrough (D = 0 after discretisation;"
            " Tustin adds feedthrough: use zoh)"
        )
    if obs.method == "kalman":
        L, M, record = _kalman(spec, d)
    elif obs.method == "luenberger":
        L, M, record = _luenberger(spec, d)
    elif obs.form == "current":
        L, M, record = d.A @ obs.M, obs.M, {"method": "given"}
    else:
        L, M, record = obs.L, None, {"method": "given"}
    return L, (M if obs.form == "current" else None), record


def _kalman(spec: PlantSpec, d: Discretised) -> tuple[np.ndarray, np.ndarray, dict]:
    import control

    obs = spec.observer
    n = d.A.shape[0]
    G = d.B if obs.G_is_B else (np.eye(n) if obs.G is None else obs.G)
    check_psd(obs.W, "observer W (process noise covariance)", definite=False)
    check_psd(obs.V, "observer V (measurement noise covariance)", definite=True)
    try:
        P, _, _ = control.dare(d.A.T, d.C.T, G @ obs.W @ G.T, obs.V)
    except Exception as exc:  # SLICOT/SciPy report failures with assorted exception types
        raise DesignError(f"Kalman DARE failed: {str(exc).splitlines()[0]} (is (A, G) stabilizable?)") from None
    P = np.asarray(P, float)
    M = P @ d.C.T @ np.linalg.inv(d.C @ P @ d.C.T + obs.V)
    record = {"method": "kalman", "W": matrix_to_json(obs.W), "V": matrix_to_json(obs.V)}
    if obs.G_given:
        record["G"] = matrix_to_json(G)
    return d.A @ M, M, record


def _luenberger(spec: PlantSpec, d: Discretised) -> tuple[np.ndarray, np.ndarray | None, dict]:
    import control

    poles = spec.observer.poles_z
    try:
        L = np.real(np.asarray(control.place(d.A.T, d.C.T, poles), complex)).T
    except Exception as exc:  # python-control reports placement failures with assorted exception types
        raise DesignError(f"observer pole placement failed: {str(exc).splitlines()[0]}") from None
    M = None
    if spec.observer.form == "current":
        if np.linalg.cond(d.A) > 1e12:
            raise DesignError("current-form Luenberger observer needs an invertible Ad")
        M = np.linalg.solve(d.A, L)
    return L, M, {"method": "luenberger", "poles": complex_pairs(poles)}
