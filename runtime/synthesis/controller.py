"""The state-feedback gain ``[K Ki]`` on the plant augmented with integrators: DLQR, pole placement, or the
user's own gains."""

from __future__ import annotations

import numpy as np

from ..errors import DesignError
from ..shipping.artifact import matrix_to_json
from ..spec import PlantSpec
from .analysis import complex_pairs
from .riccati import solve_dlqr


def check_psd(W: np.ndarray, what: str, *, definite: bool) -> None:
    """Symmetric and positive (semi)definite, else DesignError naming ``what`` and the smallest eigenvalue."""
    if not np.allclose(W, W.T, rtol=1e-10, atol=1e-12):
        raise DesignError(f"{what} is not symmetric")
    eig = np.linalg.eigvalsh((W + W.T) / 2)
    scale = max(1.0, float(np.max(np.abs(eig))))
    if definite and eig[0] <= 1e-12 * scale:
        raise DesignError(f"{what} is not positive definite (smallest eigenvalue {eig[0]:.3g})")
    if not definite and eig[0] < -1e-10 * scale:
        raise DesignError(f"{what} is not positive semi-definite (smallest eigenvalue {eig[0]:.3g})")


def controller_gain(spec: PlantSpec, Aa: np.ndarray, Ba: np.ndarray, warnings: list[str]) -> tuple[np.ndarray, dict]:
    """``Ka = [K Ki]`` for the augmented plant ``(Aa, Ba)`` and the design record of the artifact."""
    ctl = spec.controller
    q = spec.q
    if ctl.method in ("lqr", "mpc"):  # MPC: the LQ gain it reduces to with no constraint active
        return _lqr(spec, Aa, Ba, warnings)
    if ctl.method in ("place", "ackermann"):
        return _placed(spec, Aa, Ba, warnings)
    return np.hstack([ctl.K, ctl.Ki]), {"method": "given", "augmented": bool(q)}


def _lqr(spec: PlantSpec, Aa: np.ndarray, Ba: np.ndarray, warnings: list[str]) -> tuple[np.ndarray, dict]:
    q, n = spec.q, spec.plant.n
    Q = spec.controller.Q
    if q:
        Q = np.block([[Q, np.zeros((n, q))], [np.zeros((q, n)), spec.integral.Qz]])
    R = spec.controller.R
    check_psd(Q, "controller Q", definite=False)
    check_psd(R, "controller R", definite=True)
    K = solve_dlqr(Aa, Ba, Q, R, states=_augmented_names(spec), warnings=warnings)
    return K, {"method": spec.controller.method, "Q": matrix_to_json(Q), "R": matrix_to_json(R), "augmented": bool(q)}


def _augmented_names(spec: PlantSpec) -> list[str]:
    tracked = [spec.plant.outputs[i] for i in spec.integral.outputs] if spec.integral else []
    return list(spec.plant.states) + [f"integral of {name}" for name in tracked]


def _placed(spec: PlantSpec, Aa: np.ndarray, Ba: np.ndarray, warnings: list[str]) -> tuple[np.ndarray, dict]:
    import control

    method, poles = spec.controller.method, spec.controller.poles_z
    if method == "ackermann":
        warnings.append("Ackermann's formula is numerically fragile for more than a few states; prefer 'place'")
        K = np.atleast_2d(control.acker(Aa, Ba, poles))
    else:
        try:
            K = control.place(Aa, Ba, poles)
        except Exception as exc:  # python-control reports placement failures with assorted exception types
            raise DesignError(f"pole placement failed: {str(exc).splitlines()[0]}") from None
    record = {"method": method, "poles": complex_pairs(poles), "augmented": bool(spec.q)}
    return np.real(np.asarray(K, complex)).astype(float), record
