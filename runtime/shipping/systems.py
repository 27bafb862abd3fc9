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

if TYPE_CHECKING:
    import control

    from .artifact import Artifact


def controller_matrices(a: Artifact) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C, D)`` of the unsaturated law from ``[dy; dr]`` to ``du`` on the state ``[xh; z]``."""
    n, m, p, q = a.n, a.m, a.p, a.q
    if a.observer_form == "current":
        Xy = a.M  # xc = Xx xh + Xy dy
        Xx = np.eye(n) - a.M @ a.Cd
        F, G, Ly = a.Ad @ Xx, a.Bd, a.Ad @ a.M  # xh+ = F xh + G du + Ly dy
    else:
        Xx, Xy = np.eye(n), np.zeros((n, p))
        F, G, Ly = a.Ad - a.L @ a.Cd, a.Bd - a.L @ a.Dd, a.L
    # du = -K Xx xh - K Xy dy - Ki z
    Cu = np.hstack([-a.K @ Xx, -a.Ki])
    Du = np.hstack([-a.K @ Xy, np.zeros((m, q))])
    A = np.block([[F + G @ Cu[:, :n], G @ Cu[:, n:]], [np.zeros((q, n)), np.eye(q)]])
    B = np.block([[Ly + G @ Du[:, :p], np.zeros((n, q))], [-a.Ts * a.Ci, a.Ts * np.eye(q)]])
    return A, B, Cu, Du


def controller_system(a: Artifact) -> control.StateSpace:
    """The unsaturated law as a discrete ``control.StateSpace`` from ``(y, r)`` to ``u``, named signals."""
    import control

    A, B, C, D = controller_matrices(a)
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
