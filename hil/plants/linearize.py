"""Linearise an FMU about an operating point into a plant spec that ``gainlink design`` takes.

The spec's ``[operating_point]`` table records the point by signal name: ``u_op`` (the inputs there),
``y_op`` (the outputs there) and ``x_op`` (the states there), so the designed loop works in the FMU's
absolute units. When ``--at`` gives no state and the FMU's start is not at rest, the point is the
equilibrium with the inputs held (Newton's method on ``dx/dt = 0``; e.g. a mass on a spring that starts
displaced is linearised where the spring holds it). A point that is still not an equilibrium (a state was
given, or no equilibrium was found) is linearised all the same, with a warning: the linear model about it
drifts, and the loop will settle elsewhere.

The FMU's Model Exchange interface (FMI 2.0 or 3.0) gives ``dx/dt = f(x, u)`` and ``y = g(x, u)``; the
Jacobians come from its directional derivatives when it provides them, else from central differences
(:mod:`gainlink.hil.plants.jacobian`). fmpy has no linearisation of its own (FIELD-NOTES). A
Co-Simulation-only FMU gets a discrete model at the step ``Ts``, identified from ``doStep`` responses out of a
saved state (:mod:`gainlink.hil.plants.identify`), or a one-line refusal when it cannot save its state.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError, SpecError
from gainlink.fileio import atomic_write_text, read_toml
from gainlink.lti import StateSpaceModel

from . import toml_write
from .fmi import read_description, resolve_fmu, signal_name
from .fmi_me import check_model_exchange, provides_directional
from .jacobian import Signals, jacobians, signals
from .validity import Validity, check_linearization

log = logging.getLogger(__name__)

DESIGN_SECTIONS = ("controller", "integral", "observer", "limits")


@dataclass(frozen=True, kw_only=True)
class Linearization(StateSpaceModel):
    """A model about ``point`` (the values set) with the method used; ``Ts`` is the step of a discrete model
    (Co-Simulation FMUs), None for a continuous one."""

    point: dict
    x0: np.ndarray
    method: str
    model_name: str
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
                table[key] = {signal_name(n): float(v) for n, v in zip(names, values)}
        return table


def fmu_path(fmu: str | Path) -> Path:
    """The FMU file of ``fmu``: a path, or the name of one of the project's FMUs (built when missing)."""
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
    path = fmu_path(fmu)
    md = read_description(path)
    _check_declared_ranges(md, at or {})
    if md.fmiVersion in ("2.0", "3.0") and md.modelExchange is None and md.coSimulation is not None:
        return _linearize_cosimulation(
            path, md, at=at or {}, inputs=inputs, outputs=outputs, method=method, Ts=Ts, horizon=horizon
        )
    use_dd = _check_model_exchange(path, md, method)
    sig = signals(md, inputs=inputs, outputs=outputs, at=at)
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


def _check_declared_ranges(md: Any, at: Mapping[str, float]) -> None:
    """Refuse an operating-point value that is not finite or lies outside the variable's declared min/max
    (on the variable, else on its declared type): a negative mass is not a point to linearise about."""
    vars_ = {v.name: v for v in md.modelVariables}
    for name, value in at.items():
        v = vars_.get(name)
        if v is None:
            continue  # unknown names are refused with the list of variables further on
        if not np.isfinite(value):
            raise PlantError(f"FMU {md.modelName}: operating point {name} = {value} is not a finite number")
        lo, hi = (_declared(v, key) for key in ("min", "max"))
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            declared = ", ".join(f"{k} {b:g}" for k, b in (("min", lo), ("max", hi)) if b is not None)
            raise PlantError(
                f"FMU {md.modelName}: operating point {name} = {value:g} is outside the range the FMU declares for it "
                f"({declared})"
            )


def _declared(v: Any, key: str) -> float | None:
    """A variable's declared bound ``key`` ("min"/"max") as a float, from the variable or its declared type."""
    raw = getattr(v, key, None)
    if raw is None and getattr(v, "declaredType", None) is not None:
        raw = getattr(v.declaredType, key, None)
    try:
        return None if raw is None else float(raw)
    except (TypeError, ValueError):
        return None


def _check_model_exchange(path: Path, md: Any, method: str) -> bool:
    """What linearize needs of a Model Exchange FMU; True when directional derivatives are to be used."""
    check_model_exchange(path, md)
    if not md.derivatives:
        raise PlantError(f"FMU {path} declares no continuous states (ModelStructure/Derivatives is empty)")
    if method not in ("auto", "directional", "differences"):
        raise PlantError(f"unknown linearisation method {method!r}")
    provides = provides_directional(path, md)
    if method == "directional" and not provides:
        raise PlantError(f"FMU {md.modelName} does not provide directional derivatives")
    return provides and method != "differences"


def _evaluate(path: Path, md: Any, sig: Signals, *, use_dd: bool) -> Linearization:
    """The Jacobians at the point (moved to the equilibrium when needed) as a :class:`Linearization`."""
    j = jacobians(path, md, sig, use_dd=use_dd)
    return Linearization(
        A=j.A,
        B=j.B,
        C=j.C,
        D=j.D,
        states=tuple(s.name for s in sig.states),
        inputs=tuple(sig.inputs),
        outputs=tuple(sig.outputs),
        point=sig.point,
        x0=j.x0,
        method=j.method,
        model_name=md.modelName,
        u0=j.u0,
        y0=j.y0,
        dx0=j.dx0,
    )


def _check_finite(md: Any, lin: Linearization) -> None:
    if not all(np.all(np.isfinite(M)) for M in (lin.A, lin.B, lin.C, lin.D)):
        raise PlantError(f"FMU {md.modelName}: the Jacobian at this point holds non-finite entries")
    if not all(np.all(np.isfinite(v)) for v in (lin.x0, lin.u0, lin.y0, lin.dx0)):
        raise PlantError(f"FMU {md.modelName}: a state, input or output at this point is not finite")


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
            "states": [signal_name(s) for s in lin.states],
            "inputs": [signal_name(s) for s in lin.inputs],
            "outputs": [signal_name(s) for s in lin.outputs],
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


@dataclass(frozen=True)
class SpecWritten:
    """What ``linearize`` wrote: the linearisation, and the check of it (interface, fit) the spec records."""

    lin: Linearization
    validity: Validity

    def to_json(self) -> dict:
        """``linearize --json``: sizes, method, operating point and the ``[linearization]`` record."""
        lin = self.lin
        return {
            "n": int(lin.A.shape[0]),
            "m": int(lin.B.shape[1]),
            "p": int(lin.C.shape[0]),
            "method": lin.method,
            "operating_point": lin.operating_point(),
            "linearization": self.validity.record,
        }


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
    interface: str = "auto",
) -> SpecWritten:
    """Linearise, check the model against the FMU (:mod:`.validity`: the interface runs at ``Ts`` will use, the
    fit through it) and write the spec TOML with its ``[linearization]`` record (atomically); the spec parses
    with :func:`gainlink.spec.parse_spec`. A poor fit is logged as one warning line."""
    from gainlink.spec import parse_spec

    if not Ts > 0:
        raise SpecError("--Ts must be positive")
    if interface not in ("auto", "cs", "me"):
        raise PlantError(f"linearize: --interface must be auto, cs or me, not {interface!r}")
    lin = linearize(fmu, at=at, inputs=inputs, outputs=outputs, method=method, Ts=Ts, horizon=horizon)
    tmpl = _template(template)
    data = spec_dict(lin, Ts=Ts, name=name, template=tmpl)
    parse_spec(data, source=str(out))  # refuse to write a spec design would not take
    path = fmu_path(fmu)
    validity = check_linearization(lin, path=path, md=read_description(path), Ts=Ts, interface=interface)
    data["linearization"] = validity.record
    parse_spec(data, source=str(out))
    if validity.warning():
        log.warning("FMU %s: %s", lin.model_name, validity.warning())
    atomic_write_text(out, toml_write.dumps(data, header=_header(lin, validity, template=tmpl is not None)))
    return SpecWritten(lin=lin, validity=validity)


def _template(template: Path | None) -> dict | None:
    if template is None:
        return None
    return read_toml(template, what="template spec", error=SpecError)[0]


def _header(lin: Linearization, validity: Validity, *, template: bool) -> str:
    """The comment at the top of the spec: where it came from, the point, and what was checked."""
    states_there = (
        "states are balanced coordinates of the identified discrete model (D = 0: outputs sampled after each step)"
        if lin.Ts is not None
        else f"states there: {', '.join(f'{s} = {v:g}' for s, v in zip(lin.states, lin.x0))}"
    )
    drift = _drift(lin.dx0, A=lin.A, B=lin.B, states=lin.states) if lin.dx0 is not None else ""
    fit = validity.fit
    return (
        f"Linearised from FMU {lin.model_name} by gainlink linearize ({lin.method}).\n"
        f"Operating point: {', '.join(f'{k} = {v:g}' for k, v in lin.point.items()) or 'start values'}; "
        f"{states_there}.\n"
        "[operating_point] holds the inputs and outputs there: the loop works in absolute units.\n"
        + (f"Not an equilibrium: {drift}.\n" if drift else "")
        + f"Runs at Ts = {fit.Ts:g} s simulate the FMU through {validity.choice.interface}: "
        f"{validity.choice.reason}.\n"
        + f"Fit of the model to the FMU there (worst NRMSE or final error): {fit.worst:.2g}"
        + (" - POOR, see fit_warning.\n" if fit.poor else ".\n")
        + (
            "Design sections copied from the template spec."
            if template
            else "Design sections are neutral defaults: edit weights, noise and limits before designing."
        )
    )
