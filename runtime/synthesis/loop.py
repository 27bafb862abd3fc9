"""The combined loop of plant, observer and controller: its state matrix, the separation check, stability."""

from __future__ import annotations

import numpy as np

from ..errors import DesignError
from .discretize import Discretised

POLE_MATCH_TOL = 1e-6


def closed_loop_matrix(
    d: Discretised, *, K, Ki, L, M, Ci, Ts: float, form: str, break_input: int | None = None
) -> np.ndarray | tuple:
    """State matrix of plant + observer + controller on the state ``[x; xh; z]`` (linear, r = 0).

    With ``break_input = i`` returns ``(A, B, C)`` of the loop broken at plant input i, where an
    actuator would change it: input ``w`` drives plant input i, output is the controller's command
    for input i, and the observer keeps being fed the controller's own command (as the C loop is:
    it never sees the actuator). Margins of that loop are margins against actuator gain and phase.
    """
    n, m = d.B.shape
    q = Ci.shape[0]
    Ad, Bd, Cd, Dd = d.A, d.B, d.C, d.D
    if form == "current":
        # xc = xh + M (Cd x - Cd xh); v = -K xc - Ki z; xh+ = Ad xc + Bd v
        V = np.hstack([-K @ M @ Cd, -K @ (np.eye(n) - M @ Cd), -Ki])
        Lx, Ah = Ad @ M @ Cd, Ad @ (np.eye(n) - M @ Cd)
        obs_sees_plant_input = np.zeros((n, m))  # Dd = 0 in the current form
        obs_own = Bd
    else:
        # v = -K xh - Ki z; xh+ = (Ad - L Cd) xh + L Cd x + (Bd - L Dd) v + L Dd u_plant
        V = np.hstack([np.zeros((m, n)), -K, -Ki])
        Lx, Ah = L @ Cd, Ad - L @ Cd
        obs_sees_plant_input = L @ Dd
        obs_own = Bd - L @ Dd
    A0 = np.block(
        [
            [Ad, np.zeros((n, n)), np.zeros((n, q))],
            [Lx, Ah, np.zeros((n, q))],
            [-Ts * Ci @ Cd, np.zeros((q, n)), np.eye(q)],
        ]
    )
    B_plant = np.vstack([Bd, obs_sees_plant_input, -Ts * Ci @ Dd])  # what the plant's input drives
    B_own = np.vstack([np.zeros((n, m)), obs_own, np.zeros((q, m))])  # the observer's copy of the command
    if break_input is None:
        return A0 + (B_plant + B_own) @ V
    S = np.eye(m)
    S[break_input, break_input] = 0.0
    e = np.zeros((m, 1))
    e[break_input] = 1.0
    return A0 + B_plant @ S @ V + B_own @ V, B_plant @ e, V[break_input : break_input + 1, :]


def check_separation(Acl: np.ndarray, A_ctrl: np.ndarray, A_obs: np.ndarray, rtol: float = 1e-9) -> None:
    """Verify that the combined loop is the controller and observer dynamics, and nothing else.

    In coordinates ``[x; z; e]`` with ``e = x - xh`` the matrix of :func:`closed_loop_matrix` must be
    block upper-triangular with diagonal blocks ``A_ctrl = Aa - Ba Ka`` and ``A_obs = Ad - L Cd``, so
    its eigenvalues are exactly their union. Comparing matrices is well conditioned where comparing
    clustered eigenvalues of a non-normal matrix is not.
    """
    n = A_obs.shape[0]
    q = A_ctrl.shape[0] - n
    N = 2 * n + q
    # [x; z; e] = T [x; xh; z]
    T = np.zeros((N, N))
    T[:n, :n] = np.eye(n)
    T[n : n + q, 2 * n :] = np.eye(q)
    T[n + q :, :n] = np.eye(n)
    T[n + q :, n : 2 * n] = -np.eye(n)
    At = T @ Acl @ np.linalg.inv(T)
    scale = max(1.0, float(np.linalg.norm(Acl)))
    errors = {
        "controller block": np.linalg.norm(At[: n + q, : n + q] - A_ctrl),
        "observer block": np.linalg.norm(At[n + q :, n + q :] - A_obs),
        "coupling of the estimation error into the plant": np.linalg.norm(At[n + q :, : n + q]),
    }
    for what, err in errors.items():
        if err > rtol * scale:
            raise DesignError(f"closed loop is not the union of controller and observer: {what} off by {err:.3g}")


def closed_loop_poles(d: Discretised, A_ctrl: np.ndarray, gains: dict) -> tuple[np.ndarray, float]:
    """Closed-loop poles and spectral radius; DesignError when unstable (naming the part that is: the controller
    with the plant, the observer, or both, with the offending eigenvalue) or when the separation principle fails."""
    Acl = closed_loop_matrix(d, **gains)
    cl_poles = np.linalg.eigvals(Acl)
    radius = float(np.max(np.abs(cl_poles)))
    if not radius < 1.0:
        raise DesignError(
            f"closed loop is unstable: spectral radius {radius:.6g} >= 1 ({_unstable_parts(d, A_ctrl, gains)})"
        )
    check_separation(Acl, A_ctrl, d.A - gains["L"] @ d.C)
    return cl_poles, radius


def _unstable_parts(d: Discretised, A_ctrl: np.ndarray, gains: dict) -> str:
    """Which of the loop's two parts has eigenvalues on or outside the unit circle, and the largest of each."""
    parts = []
    for what, A in (
        ("the controller with the plant (A - B K)", A_ctrl),
        ("the observer (A - L C)", d.A - gains["L"] @ d.C),
    ):
        eig = np.linalg.eigvals(A)
        worst = eig[int(np.argmax(np.abs(eig)))]
        if abs(worst) >= 1.0:
            parts.append(f"{what}: eigenvalue {_fmt(worst)}, |z| = {abs(worst):.6g}")
    if not parts:
        return "the controller and the observer are each stable: their coupling is not"
    return "unstable: " + "; and ".join(parts)


def _fmt(z: complex) -> str:
    z = complex(z)
    return f"{z.real:.6g}" if abs(z.imag) < 1e-12 else f"{z.real:.6g}{z.imag:+.6g}j"


def poles_match(a: np.ndarray, b: np.ndarray, tol: float = POLE_MATCH_TOL) -> bool:
    """True when the multisets a and b of complex numbers agree (greedy nearest matching)."""
    if len(a) != len(b):
        return False
    rest = list(b)
    for z in a:
        j = int(np.argmin([abs(z - w) for w in rest]))
        if abs(z - rest[j]) > tol * max(1.0, abs(z)):
            return False
        rest.pop(j)
    return True
