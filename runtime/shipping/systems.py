"""An artifact's law and loop as python-control systems, for margins and responses in python-control.

The law is linear while no input saturates; these systems are that linear law in deviation
variables (``dy = y - y_op``, ``dr = r - Ci y_op``, ``du = u - u_op``), sampled at ``Ts``, with the
signal names of the artifact. State: the estimate ``xh`` then the integrators ``z``.

Predictor form: ``du = -K xh - Ki z``, ``xh+ = (Ad - L Cd) xh + (Bd - L Dd) du + L dy``.
Current form: ``xc = (I - M Cd) xh + M dy``, ``du = -K xc - Ki z``, ``xh+ = Ad xc + Bd du``.
Integrators: ``z+ = z + Ts (dr - Ci dy)`` (anti-windup is inactive without saturation).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .law_c import law_pair
from .scheduled import law_coefficients

if TYPE_CHECKING:
    import control

    from .artifact import Artifact


def controller_matrices(
    a: Artifact, sigma: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C, D)`` of the unsaturated law from ``[dy; dr]`` to ``du`` on the state ``[xh; z]`` (a scheduled
    artifact: the frozen-point law at ``sigma``, its coefficients interpolated there)."""
    return _COEFFICIENTS[law_pair(a)[0]](a, sigma)


def _lq_coefficients(a: Artifact, sigma: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The lq law's: its one positional law's coefficients."""
    c = law_coefficients(
        Ad=a.Ad, Bd=a.Bd, Cd=a.Cd, Dd=a.Dd, K=a.K, L=a.L, M=a.M, Ki=a.Ki, Ts=a.Ts, form=a.observer_form
    )
    return coefficient_law(c["F"], c["G"], c["Ly"], c["Kx"], c["Ky"], a.Ki, Ci=a.Ci, Ts=a.Ts)


def _scheduled_coefficients(a: Artifact, sigma: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The scheduled law's: its points' coefficients interpolated at ``sigma``."""
    c = a.schedule.coefficients_at(sigma)
    return coefficient_law(c["F"], c["G"], c["Ly"], c["Kx"], c["Ky"], c["Kz"] / a.Ts, Ci=a.Ci, Ts=a.Ts)


#: Each structure's frozen-point coefficients (the registry :func:`controller_matrices` asks).
#: The MPC law's is its unconstrained one: with no box active its optimum is the lq law of the same weights.
_COEFFICIENTS = {"lq": _lq_coefficients, "scheduled": _scheduled_coefficients, "mpc": _lq_coefficients}


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
