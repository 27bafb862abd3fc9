"""An artifact's law and loop as python-control systems, for margins and responses in python-control.

The law is linear while no input saturates; these systems are that linear law in deviation
variables (``dy = y - y_op``, ``dr = r - Ci y_op``, ``du = u - u_op``), sampled at ``Ts``, with the
signal names of the artifact. State: the estimate ``xh`` then the integrators ``z``.

Predictor form: ``du = -K xh - Ki z``, ``xh+ = (Ad - L Cd) xh + (Bd - L Dd) du + L dy``.
Current form: ``xc = (I - M Cd) xh + M dy``, ``du = -K xc - Ki z``, ``xh+ = Ad xc + Bd du``.
Integrators: ``z+ = z + Ts (dr - Ci dy)`` (anti-windup is inactive without saturation).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..registry import LawTable
from .law_c import law_pair

if TYPE_CHECKING:
    import control

    from .artifact import Artifact


def controller_matrices(
    a: Artifact, sigma: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C, D)`` of the unsaturated law from ``[dy; dr]`` to ``du`` on the state ``[xh; z]`` (a scheduled
    artifact: the frozen-point law at ``sigma``, its coefficients interpolated there)."""
    return COEFFICIENTS[law_pair(a)[0]](a, sigma)


def law_coefficients(*, Ad, Bd, Cd, Dd, K, L, M, Ki, Ts: float, form: str) -> dict[str, np.ndarray]:
    """``F G Ly Kx Ky Kz`` of one point's positional law (predictor: ``F = Ad - L Cd``, ``G = Bd - L Dd``,
    ``Ly = L``, ``Kx = K``, ``Ky = 0``; current: ``F = Ad (I - M Cd)``, ``G = Bd``, ``Ly = Ad M``, ``Kx = K (I - M
    Cd)``, ``Ky = K M``; ``Kz = Ts Ki``): what the scheduled law interpolates, and the lq law's frozen form."""
    n = Ad.shape[0]
    if form == "current":
        X = np.eye(n) - M @ Cd
        out = {"F": Ad @ X, "G": Bd.copy(), "Ly": Ad @ M, "Kx": K @ X, "Ky": K @ M}
    else:
        out = {
            "F": Ad - L @ Cd,
            "G": Bd - L @ Dd,
            "Ly": L.copy(),
            "Kx": K.copy(),
            "Ky": np.zeros((K.shape[0], Cd.shape[0])),
        }
    out["Kz"] = Ts * Ki
    return out


def lq_coefficients(a: Artifact, sigma: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The lq law's: its one positional law's coefficients."""
    c = law_coefficients(
        Ad=a.Ad, Bd=a.Bd, Cd=a.Cd, Dd=a.Dd, K=a.K, L=a.L, M=a.M, Ki=a.Ki, Ts=a.Ts, form=a.observer_form
    )
    return coefficient_law(c["F"], c["G"], c["Ly"], c["Kx"], c["Ky"], a.Ki, Ci=a.Ci, Ts=a.Ts)


#: Each structure's frozen-point coefficients ``(a, sigma) -> (A, B, C, D)`` (the table :func:`controller_matrices`
#: asks), registered by the law families (:mod:`gainlink.registry`). The MPC law's is :func:`lq_coefficients`: with no
#: box active its optimum is the lq law of the same weights.
COEFFICIENTS: LawTable[Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = LawTable(
    "frozen-point coefficients"
)


def coefficient_law(F, G, Ly, Kx, Ky, Ki, *, Ci, Ts: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C, D)`` of ``du = -Kx xh - Ky dy - Ki z``, ``xh+ = F xh + G du + Ly dy``, ``z+ = z + Ts (dr - Ci dy)``
    from ``[dy; dr]`` to ``du`` on the state ``[xh; z]``."""
    n, q = F.shape[0], Ci.shape[0]
    Cu = np.hstack([-Kx, -Ki])
    Du = np.hstack([-Ky, np.zeros((Kx.shape[0], q))])
    A = np.block([[F + G @ Cu[:, :n], G @ Cu[:, n:]], [np.zeros((q, n)), np.eye(q)]])
    B = np.block([[Ly + G @ Du[:, : Ly.shape[1]], np.zeros((n, q))], [-Ts * Ci, Ts * np.eye(q)]])
    return A, B, Cu, Du


def controller_system(a: Artifact, sigma: float | None = None) -> control.StateSpace:
    """The unsaturated law as a discrete ``control.StateSpace`` from ``(y, r)`` to ``u``, named signals (a
    scheduled artifact: frozen at ``sigma``)."""
    import control

    A, B, C, D = controller_matrices(a, sigma)
    sig = a.signals
    realised = "realization" in a.data  # the estimate in other coordinates than the plant's states
    states = ([f"xh{i}" for i in range(a.n)] if realised else [f"xh_{s}" for s in sig["states"]]) + [
        f"z_{r}" for r in sig["references"]
    ]
    return control.ss(
        A,
        B,
        C,
        D,
        a.Ts,
        name=f"{a.name}_controller",
        states=states,
        inputs=list(sig["outputs"]) + list(sig["references"]),
        outputs=list(sig["inputs"]),
    )


def plant_system(a: Artifact) -> control.StateSpace:
    """The artifact's discrete design plant (deviation variables, the design's coordinates) with named signals."""
    import control

    sig = a.signals
    return control.ss(
        *a.design_plant(),
        a.Ts,
        name=f"{a.name}_plant",
        states=[f"x_{s}" for s in sig["states"]],
        inputs=[f"{s}_plant" for s in sig["inputs"]],
        outputs=list(sig["outputs"]),
    )


def closed_loop_system(a: Artifact) -> control.StateSpace:
    """Plant + law, unsaturated: inputs the references and an additive disturbance ``d_<input>`` at each
    plant input, outputs the plant outputs and the commands."""
    import control

    sig = a.signals
    inputs = list(sig["inputs"])
    sums = [control.summing_junction(inputs=[u, f"d_{u}"], output=f"{u}_plant", name=f"sum_{u}") for u in inputs]
    inplist = list(sig["references"]) + [f"d_{u}" for u in inputs]
    outlist = list(sig["outputs"]) + inputs
    return control.interconnect(
        [plant_system(a), controller_system(a), *sums],
        name=f"{a.name}_closed_loop",
        inplist=inplist,
        outlist=outlist,
        inputs=inplist,
        outputs=outlist,
    )
