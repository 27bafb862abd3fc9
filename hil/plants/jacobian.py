"""The Jacobians of an FMU's Model Exchange equations at a point (FMI 2.0 and 3.0): what linearisation
(:mod:`.linearize`) and the interface check (:mod:`.fmu_check`) read from an FMU.

The Model Exchange interface gives ``dx/dt = f(x, u)`` and ``y = g(x, u)``. ``A = df/dx, B = df/du, C = dg/dx,
D = dg/du`` come from the FMU's directional derivatives when it provides them, else from central differences
(step ``1e-6 * max(1, |v|)``). When no state is given and the start is not at rest, the point can move to the
equilibrium with the inputs held (Newton's method on ``dx/dt = 0``).
"""

from __future__ import annotations

import ctypes
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from .fmi_me import ModelExchange

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Signals:
    """The variables a Model Exchange linearisation reads and writes."""

    vars: dict
    states: list  # fmpy ScalarVariables of the continuous states
    derivatives: list  # and of their derivatives
    inputs: list[str]
    outputs: list[str]
    point: dict


def real_type(md: Any) -> str:
    """``Real`` (FMI 2.0) or ``Float64`` (FMI 3.0): the variables a plant drives and samples."""
    return "Float64" if md.fmiVersion == "3.0" else "Real"


def signals(md: Any, *, inputs: list[str] | None, outputs: list[str] | None, at: Mapping[str, float] | None) -> Signals:
    """Check the chosen inputs, outputs and operating-point names against the model description."""
    rt = real_type(md)
    vars_ = {v.name: v for v in md.modelVariables}
    all_in = [v.name for v in md.modelVariables if v.causality == "input" and v.type == rt]
    all_out = [v.name for v in md.modelVariables if v.causality == "output" and v.type == rt]
    in_names = list(inputs) if inputs else all_in
    out_names = list(outputs) if outputs else all_out
    for what, names, pool in (("input", in_names, all_in), ("output", out_names, all_out)):
        bad = [n for n in names if n not in pool]
        if bad:
            raise PlantError(f"FMU {md.modelName} has no Real {what} {', '.join(bad)} (has: {', '.join(pool)})")
    point = dict(at or {})
    for k in point:
        if k not in vars_ or vars_[k].type != rt:
            raise PlantError(f"FMU {md.modelName} has no Real variable {k!r} for the operating point")
    return Signals(
        vars=vars_,
        states=[d.variable.derivative for d in md.derivatives],
        derivatives=[d.variable for d in md.derivatives],
        inputs=in_names,
        outputs=out_names,
        point=point,
    )


@dataclass(frozen=True)
class Jacobians:
    """``A, B, C, D`` at the state ``x0`` and inputs ``u0``, with the outputs ``y0`` and derivatives ``dx0``
    there; ``method`` names how they were taken, ``moved`` whether the point moved to an equilibrium."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    x0: np.ndarray
    u0: np.ndarray
    y0: np.ndarray
    dx0: np.ndarray
    method: str
    moved: bool


def jacobians(path: Path, md: Any, sig: Signals, *, use_dd: bool, to_equilibrium: bool = True) -> Jacobians:
    """Instantiate the FMU at ``sig.point``, move to the equilibrium when asked and needed, take the Jacobians."""
    messages: list[str] = []
    me = ModelExchange(path, md, messages=messages, key=id(messages))
    try:
        _initialise(me, sig)
        f, x0, u0, vr = _dynamics(me, sig)
        dx0, y0 = f(x0, u0)  # set through the states, so every FMU evaluates them at the point
        moved = False
        # Not at rest and no state given: move to the equilibrium with the inputs held (the rest point an
        # FMU's start values often only approximate); with a state given, that is the point asked for.
        if to_equilibrium and not any(s.name in sig.point for s in sig.states) and np.any(np.abs(dx0) > 0.0):
            x_eq = equilibrium(f, x0, u0)
            if x_eq is not None:
                log.info(
                    "FMU %s: the start point is not an equilibrium; linearising at the equilibrium with the "
                    "inputs held (states %s)",
                    md.modelName,
                    np.array2string(x_eq, precision=6),
                )
                x0, moved = x_eq, True
                dx0, y0 = f(x0, u0)
        if use_dd:
            (A, B, C, D), name = _directional_jacobians(me, vr), "directional derivatives"
        else:
            (A, B, C, D), name = _difference_jacobians(f, x0, u0), "central differences"
    except PlantError:
        raise
    except Exception as exc:
        reason = messages[-1] if messages else str(exc)
        raise PlantError(f"FMU {md.modelName}: linearisation failed ({reason})") from None
    finally:
        me.close()
    return Jacobians(A=A, B=B, C=C, D=D, x0=x0, u0=u0, y0=y0, dx0=dx0, method=name, moved=moved)


def _initialise(me: ModelExchange, sig: Signals) -> None:
    """Instantiate and initialise with the operating point's values, into continuous-time mode."""
    me.initialise(sig.point, vars_=sig.vars)
    needed = True
    while needed:
        needed, terminate, _, _ = me.update_discrete()
        if terminate:
            raise PlantError("the FMU asked to terminate during its initial event update")
    me.enter_continuous()


def _dynamics(me: ModelExchange, sig: Signals) -> tuple[Any, np.ndarray, np.ndarray, dict]:
    """``f(x, u) -> (dx/dt, y)`` through the FMU, the state and input at the point, and the value references."""
    vr = {
        "x": [s.valueReference for s in sig.states],
        "dx": [d.valueReference for d in sig.derivatives],
        "u": [sig.vars[n].valueReference for n in sig.inputs],
        "y": [sig.vars[n].valueReference for n in sig.outputs],
    }
    nx = len(vr["x"])
    x0 = np.array(me.get_real(vr["x"]), dtype=float)
    u0 = np.array(me.get_real(vr["u"]), dtype=float) if vr["u"] else np.zeros(0)

    def f(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        me.set_x((ctypes.c_double * nx)(*x), nx)
        if vr["u"]:
            me.set_real(vr["u"], list(u))
        dx = np.array(me.get_real(vr["dx"]), dtype=float)
        y = np.array(me.get_real(vr["y"]), dtype=float) if vr["y"] else np.zeros(0)
        return dx, y

    return f, x0, u0, vr


def _directional_jacobians(me: ModelExchange, vr: dict) -> tuple[np.ndarray, ...]:
    """A, B, C, D from the FMU's directional derivatives, one known variable at a time."""

    def jac(unknown: list[int], known: list[int]) -> np.ndarray:
        J = np.zeros((len(unknown), len(known)))
        for j, ref in enumerate(known):
            if unknown:
                J[:, j] = me.directional(unknown, [ref], [1.0])
        return J

    return jac(vr["dx"], vr["x"]), jac(vr["dx"], vr["u"]), jac(vr["y"], vr["x"]), jac(vr["y"], vr["u"])


def central_difference(g: Any, v: np.ndarray) -> np.ndarray:
    """Columns d g / d v_j by central differences (step 1e-6 relative, at least 1e-6); ``g`` returns a vector."""
    cols = []
    for j in range(v.size):
        e = np.zeros(v.size)
        e[j] = 1e-6 * max(1.0, abs(v[j]))
        cols.append((g(v + e) - g(v - e)) / (2 * e[j]))
    return np.array(cols).T if cols else np.zeros((np.asarray(g(v)).size, 0))


def _difference_jacobians(f: Any, x0: np.ndarray, u0: np.ndarray) -> tuple[np.ndarray, ...]:
    """A, B, C, D by central differences of ``f(x, u) -> (dx/dt, y)`` about (x0, u0)."""
    nx = x0.size
    stack = lambda dx_y: np.concatenate(dx_y)  # noqa: E731
    Jx = central_difference(lambda x: stack(f(x, u0)), x0)
    Ju = central_difference(lambda u: stack(f(x0, u)), u0)
    return Jx[:nx], Ju[:nx], Jx[nx:], Ju[nx:]


def equilibrium(f: Any, x0: np.ndarray, u0: np.ndarray, *, iterations: int = 30) -> np.ndarray | None:
    """Newton's method on ``dx/dt = f(x, u0) = 0`` with the inputs held, from ``x0`` (Jacobian by central
    differences); ``None`` when the Jacobian is singular or the iteration does not converge."""
    x = x0.astype(float).copy()
    for _ in range(iterations):
        dx, _ = f(x, u0)
        scale = max(1.0, float(np.max(np.abs(x))))
        J = central_difference(lambda v: f(v, u0)[0], x)
        if np.linalg.cond(J) > 1e10:
            return None
        step = np.linalg.solve(J, dx)
        x = x - step
        if np.max(np.abs(step)) <= 1e-12 * scale:
            return x if np.all(np.isfinite(x)) else None
    return None
