"""Linearise an FMU about an operating point into a plant spec that ``gainlink design`` takes.

The spec's ``[operating_point]`` table records the point by signal name: ``u_op`` (the inputs there),
``y_op`` (the outputs there) and ``x_op`` (the states there), so the designed loop works in the FMU's
absolute units. When ``--at`` gives no state and the FMU's start is not at rest, the point is the
equilibrium with the inputs held (Newton's method on ``dx/dt = 0``; e.g. a mass on a spring that starts
displaced is linearised where the spring holds it). A point that is still not an equilibrium (a state was
given, or no equilibrium was found) is linearised all the same, with a warning: the linear model about it
drifts, and the loop will settle elsewhere.

The FMU's Model Exchange interface gives ``dx/dt = f(x, u)`` and ``y = g(x, u)``. The Jacobians
``A = df/dx, B = df/du, C = dg/dx, D = dg/du`` come from ``fmi2GetDirectionalDerivative`` when the
FMU provides it, else from central differences (step ``1e-6 * max(1, |v|)``). fmpy has no
linearisation of its own (FIELD-NOTES). A Co-Simulation-only FMU gets a discrete model at the
step ``Ts``, identified from ``doStep`` responses out of a saved state
(:mod:`gainlink.hil.plants.identify`), or a one-line refusal when it cannot save its state.
"""

from __future__ import annotations

import logging
import shutil
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError, SpecError
from gainlink.fileio import atomic_write_text

from . import toml_write
from .fmi import open_binary, read_description, resolve_fmu

log = logging.getLogger(__name__)

DESIGN_SECTIONS = ("controller", "integral", "observer", "limits")


@dataclass(frozen=True)
class Linearization:
    """``A, B, C, D`` about ``point`` (the values set), with signal names and the method used."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    point: dict
    x0: np.ndarray
    method: str
    model_name: str
    Ts: float | None = None  # the step of a discrete model (Co-Simulation FMUs); None: continuous
    u0: np.ndarray | None = None  # inputs at the point
    y0: np.ndarray | None = None  # outputs at the point
    dx0: np.ndarray | None = None  # derivatives at the point (zero at an equilibrium; continuous models only)

    def operating_point(self) -> dict:
        """The spec's ``[operating_point]`` table: u_op, y_op and (continuous models) x_op by signal name.

        An identified discrete model's states are balanced coordinates, not the FMU's: no x_op then."""
        table = {}
        for key, names, values in (
            ("u_op", self.inputs, self.u0),
            ("y_op", self.outputs, self.y0),
            ("x_op", self.states, self.x0 if self.Ts is None else None),
        ):
            if values is not None and len(names):
                table[key] = {_signal_name(n): float(v) for n, v in zip(names, values)}
        return table


def _fmu_path(fmu: str | Path) -> Path:
    p = Path(fmu)
    if p.suffix == ".fmu" or p.exists() or "/" in str(fmu):
        return resolve_fmu(fmu=None, path=str(p))
    return resolve_fmu(fmu=str(fmu), path=None)


def linearize(
    fmu: str | Path,
    *,
    at: Mapping[str, float] | None = None,
    inputs: list[str] | None = None,
    outputs: list[str] | None = None,
    method: str = "auto",
    Ts: float | None = None,
    horizon: int | None = None,
) -> Linearization:
    """Linearise an FMU (path, or the name of a project FMU) about the point ``at``.

    Parameters
    ----------
    fmu : str or Path
        An ``.fmu`` file or a project FMU name (built on demand).
    at : mapping, optional
        Values of states, inputs or parameters at the operating point (others keep their start values).
    inputs, outputs : list of str, optional
        Which Real inputs/outputs to keep (default: all, in model-description order).
    method : {"auto", "directional", "differences"}
        Directional derivatives when provided (auto), forced, or central differences.
    Ts : float, optional
        Co-Simulation-only FMUs: the communication step of the identified discrete model (required there).
    horizon : int, optional
        Co-Simulation-only FMUs: steps recorded per input pulse (default 100).
    """
    path = _fmu_path(fmu)
    md = read_description(path)
    if md.fmiVersion in ("2.0", "3.0") and md.modelExchange is None and md.coSimulation is not None:
        return _linearize_cosimulation(
            path, md, at=at or {}, inputs=inputs, outputs=outputs, method=method, Ts=Ts, horizon=horizon
        )
    use_dd = _check_model_exchange(path, md, method)
    sig = _signals(md, inputs=inputs, outputs=outputs, at=at)
    lin = _evaluate(path, md, sig, use_dd=use_dd)
    _check_finite(md, lin)
    drift = _drift(lin.dx0, A=lin.A, B=lin.B, states=lin.states)
    if drift:
        log.warning(
            "FMU %s: the operating point is not an equilibrium (%s); the linear model about it "
            "drifts: set the trim (e.g. --at INPUT=VALUE) where dx/dt = 0",
            md.modelName,
            drift,
        )
    return lin


def _check_model_exchange(path: Path, md: Any, method: str) -> bool:
    """What linearize needs of a Model Exchange FMU; True when directional derivatives are to be used."""
    if md.fmiVersion != "2.0":
        raise PlantError(
            f"FMU {path} is FMI {md.fmiVersion}; linearize reads FMI 2.0 Model Exchange FMUs "
            "(and FMI 2.0/3.0 Co-Simulation-only FMUs)"
        )
    if md.modelExchange is None:
        raise PlantError(f"FMU {path} has no Model Exchange interface; linearize needs dx/dt (Model Exchange)")
    if not md.derivatives:
        raise PlantError(f"FMU {path} declares no continuous states (ModelStructure/Derivatives is empty)")
    if method not in ("auto", "directional", "differences"):
        raise PlantError(f"unknown linearisation method {method!r}")
    provides = bool(md.modelExchange.providesDirectionalDerivative)
    if method == "directional" and not provides:
        raise PlantError(f"FMU {md.modelName} does not provide directional derivatives")
    return provides and method != "differences"


@dataclass(frozen=True)
class _Signals:
    """The variables a Model Exchange linearisation reads and writes."""

    vars: dict
    states: list  # fmpy ScalarVariables of the continuous states
    derivatives: list  # and of their derivatives
    inputs: list[str]
    outputs: list[str]
    point: dict


def _signals(
    md: Any, *, inputs: list[str] | None, outputs: list[str] | None, at: Mapping[str, float] | None
) -> _Signals:
    """Check the chosen inputs, outputs and operating-point names against the model description."""
    vars_ = {v.name: v for v in md.modelVariables}
    all_in = [v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
    all_out = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    in_names = list(inputs) if inputs else all_in
    out_names = list(outputs) if outputs else all_out
    for what, names, pool in (("input", in_names, all_in), ("output", out_names, all_out)):
        bad = [n for n in names if n not in pool]
        if bad:
            raise PlantError(f"FMU {md.modelName} has no Real {what} {', '.join(bad)} (has: {', '.join(pool)})")
    point = dict(at or {})
    for k in point:
        if k not in vars_ or vars_[k].type != "Real":
            raise PlantError(f"FMU {md.modelName} has no Real variable {k!r} for the operating point")
    return _Signals(
        vars=vars_,
        states=[d.variable.derivative for d in md.derivatives],
        derivatives=[d.variable for d in md.derivatives],
        inputs=in_names,
        outputs=out_names,
        point=point,
    )


def _evaluate(path: Path, md: Any, sig: _Signals, *, use_dd: bool) -> Linearization:
    """Instantiate the FMU at the point, move to the equilibrium when needed, and take the Jacobians."""
    from fmpy.fmi2 import FMU2Model

    fmu, unzip, own = open_binary(path, md, FMU2Model, md.modelExchange.modelIdentifier)
    try:
        _initialise(fmu, sig)
        f, x0, u0, vr = _dynamics(fmu, sig)
        dx0, y0 = f(x0, u0)  # set through the states, so every FMU evaluates them at the point
        # Not at rest and no state given: move to the equilibrium with the inputs held (the rest point an
        # FMU's start values often only approximate); with a state given, that is the point asked for.
        if not any(s.name in sig.point for s in sig.states) and np.any(np.abs(dx0) > 0.0):
            x_eq = _equilibrium(f, x0, u0)
            if x_eq is not None:
                log.info(
                    "FMU %s: the start point is not an equilibrium; linearising at the equilibrium with the "
                    "inputs held (states %s)",
                    md.modelName,
                    np.array2string(x_eq, precision=6),
                )
                x0 = x_eq
                dx0, y0 = f(x0, u0)
        if use_dd:
            (A, B, C, D), name = _directional_jacobians(fmu, vr), "directional derivatives"
        else:
            (A, B, C, D), name = _difference_jacobians(f, x0, u0), "central differences"
        fmu.terminate()
    except PlantError:
        raise
    except Exception as exc:
        raise PlantError(f"FMU {md.modelName}: linearisation failed ({exc})") from None
    finally:
        try:
            fmu.freeInstance()
            fmu.freeLibrary()
        except Exception:
            log.debug("FMU cleanup failed", exc_info=True)
        if own:
            shutil.rmtree(unzip, ignore_errors=True)
    return Linearization(
        A=A,
        B=B,
        C=C,
        D=D,
        states=tuple(s.name for s in sig.states),
        inputs=tuple(sig.inputs),
        outputs=tuple(sig.outputs),
        point=sig.point,
        x0=x0,
        method=name,
        model_name=md.modelName,
        u0=u0,
        y0=y0,
        dx0=dx0,
    )


def _initialise(fmu: Any, sig: _Signals) -> None:
    """Instantiate and initialise with the operating point's values, into continuous-time mode."""
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    if sig.point:
        fmu.setReal([sig.vars[k].valueReference for k in sig.point], list(sig.point.values()))
    fmu.exitInitializationMode()
    info = fmu.newDiscreteStates()
    while info[0]:
        info = fmu.newDiscreteStates()
    fmu.enterContinuousTimeMode()


def _dynamics(fmu: Any, sig: _Signals) -> tuple[Any, np.ndarray, np.ndarray, dict]:
    """``f(x, u) -> (dx/dt, y)`` through the FMU, the state and input at the point, and the value references."""
    vr = {
        "x": [s.valueReference for s in sig.states],
        "dx": [d.valueReference for d in sig.derivatives],
        "u": [sig.vars[n].valueReference for n in sig.inputs],
        "y": [sig.vars[n].valueReference for n in sig.outputs],
    }
    nx = len(vr["x"])
    x0 = np.array(fmu.getReal(vr["x"]))
    u0 = np.array(fmu.getReal(vr["u"])) if vr["u"] else np.zeros(0)

    def f(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        fmu.setContinuousStates(fmu_real_array(x), nx)
        if vr["u"]:
            fmu.setReal(vr["u"], list(u))
        dx = np.array(fmu.getReal(vr["dx"]))
        y = np.array(fmu.getReal(vr["y"])) if vr["y"] else np.zeros(0)
        return dx, y

    return f, x0, u0, vr


def _directional_jacobians(fmu: Any, vr: dict) -> tuple[np.ndarray, ...]:
    """A, B, C, D from the FMU's directional derivatives, one known variable at a time."""

    def jac(unknown: list[int], known: list[int]) -> np.ndarray:
        J = np.zeros((len(unknown), len(known)))
        for j, ref in enumerate(known):
            if unknown:
                J[:, j] = fmu.getDirectionalDerivative(unknown, [ref], [1.0])
        return J

    return jac(vr["dx"], vr["x"]), jac(vr["dx"], vr["u"]), jac(vr["y"], vr["x"]), jac(vr["y"], vr["u"])


def _central_difference(g: Any, v: np.ndarray) -> np.ndarray:
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
    Jx = _central_difference(lambda x: stack(f(x, u0)), x0)
    Ju = _central_difference(lambda u: stack(f(x0, u)), u0)
    return Jx[:nx], Ju[:nx], Jx[nx:], Ju[nx:]


def _check_finite(md: Any, lin: Linearization) -> None:
    if not all(np.all(np.isfinite(M)) for M in (lin.A, lin.B, lin.C, lin.D)):
        raise PlantError(f"FMU {md.modelName}: the Jacobian at this point holds non-finite entries")
    if not all(np.all(np.isfinite(v)) for v in (lin.x0, lin.u0, lin.y0, lin.dx0)):
        raise PlantError(f"FMU {md.modelName}: a state, input or output at this point is not finite")


def _equilibrium(f: Any, x0: np.ndarray, u0: np.ndarray, *, iterations: int = 30) -> np.ndarray | None:
    """Newton's method on ``dx/dt = f(x, u0) = 0`` with the inputs held, from ``x0`` (Jacobian by central
    differences); ``None`` when the Jacobian is singular or the iteration does not converge."""
    x = x0.astype(float).copy()
    for _ in range(iterations):
        dx, _ = f(x, u0)
        scale = max(1.0, float(np.max(np.abs(x))))
        J = _central_difference(lambda v: f(v, u0)[0], x)
        if np.linalg.cond(J) > 1e10:
            return None
        step = np.linalg.solve(J, dx)
        x = x - step
        if np.max(np.abs(step)) <= 1e-12 * scale:
            return x if np.all(np.isfinite(x)) else None
    return None


def _drift(dx0: np.ndarray, *, A: np.ndarray, B: np.ndarray, states: tuple[str, ...]) -> str:
    """``""`` at an equilibrium, else the derivatives that are not zero (relative to the model's scale)."""
    scale = max(1.0, float(np.max(np.abs(np.hstack([A, B])), initial=0.0)))
    bad = [f"d{name}/dt = {v:.3g}" for name, v in zip(states, dx0) if abs(v) > 1e-6 * scale]
    return ", ".join(bad)


def _linearize_cosimulation(
    path: Path,
    md: Any,
    *,
    at: Mapping[str, float],
    inputs: list[str] | None,
    outputs: list[str] | None,
    method: str,
    Ts: float | None,
    horizon: int | None,
) -> Linearization:
    from .identify import DEFAULT_HORIZON, identify_cosimulation

    if method == "directional":
        raise PlantError(
            f"FMU {md.modelName} is Co-Simulation only: no directional derivatives; linearize "
            "identifies it from doStep responses (method auto or differences)"
        )
    if Ts is None:
        raise PlantError(
            f"FMU {md.modelName} is Co-Simulation only: give the communication step (--Ts) of the "
            "discrete model to identify"
        )
    if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 4):
        raise PlantError("linearize: --horizon must be a whole number of steps, at least 4")
    vars_ = {v.name: v for v in md.modelVariables}
    for k in at:
        if k not in vars_ or vars_[k].type not in ("Real", "Float64"):
            raise PlantError(f"FMU {md.modelName} has no Real variable {k!r} for the operating point")
    r = identify_cosimulation(
        path, md=md, at=at, inputs=inputs, outputs=outputs, Ts=float(Ts), horizon=horizon or DEFAULT_HORIZON
    )
    log.info(
        "identified %s: order %d, Hankel singular values %s, Markov fit %.2g",
        md.modelName,
        r["A"].shape[0],
        np.array2string(r["hankel"][: r["A"].shape[0] + 2], precision=3, max_line_width=10**6),
        r["fit"],
    )
    return Linearization(
        A=r["A"],
        B=r["B"],
        C=r["C"],
        D=r["D"],
        states=r["states"],
        inputs=tuple(r["inputs"]),
        outputs=tuple(r["outputs"]),
        point=dict(at),
        x0=np.zeros(r["A"].shape[0]),
        method=f"doStep pulse responses from a saved state, ERA order {r['A'].shape[0]}",
        model_name=md.modelName,
        Ts=float(Ts),
        u0=np.asarray(r["u0"], float),
        y0=np.asarray(r["y0"], float),
    )


def fmu_real_array(x: np.ndarray) -> Any:
    """``x`` as a ctypes ``fmi2Real`` array."""
    from fmpy.fmi2 import fmi2Real

    return (fmi2Real * len(x))(*x)


def _signal_name(name: str) -> str:
    import re

    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return s if re.match(r"[A-Za-z_]", s) else f"s_{s}"


def spec_dict(
    lin: Linearization, *, Ts: float, name: str | None = None, template: Mapping[str, Any] | None = None
) -> dict:
    """A spec mapping for ``lin``; design sections from ``template`` or neutral defaults to edit."""
    import re

    spec_name = name or re.sub(r"[^A-Za-z0-9_]", "_", lin.model_name)
    if not re.match(r"^[A-Za-z][A-Za-z0-9_]{0,31}$", spec_name):
        raise SpecError(f"spec name {spec_name!r} is not a valid name (letters, digits, underscore; 32 max)")
    n, m, p = lin.A.shape[0], lin.B.shape[1], lin.C.shape[0]
    if lin.Ts is not None and abs(lin.Ts - Ts) > 1e-12 * lin.Ts:
        raise SpecError(f"the identified model is discrete at the FMU's step {lin.Ts:g}; the spec's Ts must be that")
    data: dict[str, Any] = {
        "name": spec_name,
        "Ts": float(Ts),
        "discretization": "zoh",
        "plant": {
            "kind": "continuous" if lin.Ts is None else "discrete",
            "states": [_signal_name(s) for s in lin.states],
            "inputs": [_signal_name(s) for s in lin.inputs],
            "outputs": [_signal_name(s) for s in lin.outputs],
            "A": lin.A.tolist(),
            "B": lin.B.tolist(),
            "C": lin.C.tolist(),
            "D": lin.D.tolist(),
        },
    }
    op = lin.operating_point()
    u_op = np.array(list(op.get("u_op", {}).values()) or [0.0] * m)
    if template is not None:
        for key in DESIGN_SECTIONS:
            if key in template:
                data[key] = template[key]
    else:
        data["controller"] = {"method": "lqr", "Q_diag": [1.0] * n, "R_diag": [1.0] * m}
        data["observer"] = {"method": "kalman", "form": "predictor", "W_diag": [1e-4] * n, "V_diag": [1e-6] * p}
        data["limits"] = {"u_min": (u_op - 1e3).tolist(), "u_max": (u_op + 1e3).tolist(), "anti_windup": "clamp"}
    if op:
        data["operating_point"] = op
    return data


def linearize_to_spec(
    *,
    fmu: str | Path,
    at: Mapping[str, float],
    out: Path,
    Ts: float,
    name: str | None = None,
    inputs: list[str] | None = None,
    outputs: list[str] | None = None,
    method: str = "auto",
    template: Path | None = None,
    horizon: int | None = None,
) -> Linearization:
    """Linearise and write the spec TOML (atomically); the spec parses with :func:`gainlink.spec.parse_spec`."""
    from gainlink.spec import parse_spec

    if not Ts > 0:
        raise SpecError("--Ts must be positive")
    lin = linearize(fmu, at=at, inputs=inputs, outputs=outputs, method=method, Ts=Ts, horizon=horizon)
    tmpl = None
    if template is not None:
        try:
            tmpl = tomllib.loads(Path(template).read_text("utf-8"))
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise SpecError(f"template spec {template}: {exc}") from None
    data = spec_dict(lin, Ts=Ts, name=name, template=tmpl)
    parse_spec(data, source=str(out))  # refuse to write a spec design would not take
    states_there = (
        "states are balanced coordinates of the identified discrete model (D = 0: outputs sampled after each step)"
        if lin.Ts is not None
        else f"states there: {', '.join(f'{s} = {v:g}' for s, v in zip(lin.states, lin.x0))}"
    )
    drift = _drift(lin.dx0, A=lin.A, B=lin.B, states=lin.states) if lin.dx0 is not None else ""
    header = (
        f"Linearised from FMU {lin.model_name} by gainlink linearize ({lin.method}).\n"
        f"Operating point: {', '.join(f'{k} = {v:g}' for k, v in lin.point.items()) or 'start values'}; "
        f"{states_there}.\n"
        "[operating_point] holds the inputs and outputs there: the loop works in absolute units.\n"
        + (f"Not an equilibrium: {drift}.\n" if drift else "")
        + (
            "Design sections copied from the template spec."
            if tmpl is not None
            else "Design sections are neutral defaults: edit weights, noise and limits before designing."
        )
    )
    atomic_write_text(out, toml_write.dumps(data, header=header))
    return lin
