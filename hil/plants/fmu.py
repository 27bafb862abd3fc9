"""A plant simulated by a Co-Simulation FMU through fmpy's low-level slave loop: FMI 2.0
(``FMU2Slave``) or FMI 3.0 (``FMU3Slave``, Float64 variables).

Per step the bridge calls the raw ``fmi2SetReal`` / ``fmi2DoStep`` / ``fmi2GetReal`` (FMI 3.0:
``fmi3SetFloat64`` / ``fmi3DoStep`` / ``fmi3GetFloat64``) with ctypes arrays built once
(FIELD-NOTES: ~2.5 us per step instead of ~4.8 us through the list wrappers). Snapshots use
``fmi2GetFMUstate`` / ``fmi3GetFMUState`` when the FMU can. An FMI 2.0 FMU's log goes to
:mod:`logging`, and a failed call's :class:`PlantError` carries the FMU's last logged message.
"""

from __future__ import annotations

import logging
import shutil
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from ..registry import take_keys
from .base import PLANTS, Plant

log = logging.getLogger(__name__)


def resolve_fmu(*, fmu: str | None, path: str | None, base_dir: Path | None = None) -> Path:
    """The FMU file named by a plant config: ``fmu = "<project FMU name>"`` (built on demand) or ``path``."""
    if (fmu is None) == (path is None):
        raise PlantError("plant fmu: give exactly one of fmu (a project FMU name) or path (an .fmu file)")
    if fmu is not None:
        from .build import build_fmu

        return build_fmu(fmu)
    p = Path(path)
    if not p.is_absolute() and base_dir is not None:
        p = base_dir / p
    if not p.exists():
        raise PlantError(f"FMU {p} not found")
    return p


# FMU log messages by plant: fmpy's native logger proxy (which formats the variadic message) calls one
# global Python logger, so there is one dispatcher, keyed by the callbacks' componentEnvironment.
_FMI2_SINKS: dict[int, list[str]] = {}
_FMI2_DISPATCH: Any = None


def _fmi2_dispatch(env: Any, instance: Any, status: int, category: Any, message: bytes) -> None:
    sink = _FMI2_SINKS.get(env or 0)
    if sink is None:  # an FMU instantiated with fmpy's default callbacks: print as fmpy does
        from fmpy.fmi1 import printLogMessage

        printLogMessage(env, instance, status, category, message)
        return
    text = message.decode("utf-8", errors="replace")
    # Errors make the FMI call fail and reach the PlantError line; warnings are only logged.
    log.log(logging.WARNING if status == 1 else logging.DEBUG, "FMU: %s", text)
    if status >= 1:  # fmi2Warning and worse
        sink[:] = [text]  # the latest is the reason of a failed call


def _fmi2_callbacks(key: int, messages: list[str]) -> Any:
    """fmpy's FMI 2.0 callbacks whose logger keeps the FMU's warnings and errors in ``messages`` (so a
    failed call can name the FMU's reason); ``key`` identifies the plant in the shared dispatcher."""
    global _FMI2_DISPATCH
    from ctypes import byref, c_void_p

    from fmpy import calloc, free
    from fmpy.fmi2 import (
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
        fmi2CallbackLoggerTYPE,
    )
    from fmpy.logging import addLoggerProxy

    if _FMI2_DISPATCH is None:
        _FMI2_DISPATCH = fmi2CallbackLoggerTYPE(_fmi2_dispatch)
    _FMI2_SINKS[key] = messages
    cb = fmi2CallbackFunctions()
    cb.logger = _FMI2_DISPATCH
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    cb.componentEnvironment = c_void_p(key)
    addLoggerProxy(byref(cb))
    return cb


def read_description(path: Path) -> Any:
    """fmpy's model description of ``path``; a clear :class:`PlantError` when it is not an FMU."""
    from fmpy import read_model_description

    if p_is_zip := path.is_file():
        if not zipfile.is_zipfile(path):
            raise PlantError(f"FMU {path} is not a zip archive (broken or not an FMU)")
    try:
        return read_model_description(str(path), validate=True)
    except Exception as exc:  # fmpy raises plain Exceptions, lxml errors, KeyError, zipfile errors
        kind = "archive" if p_is_zip else "folder"
        raise PlantError(f"FMU {path}: cannot read modelDescription.xml from the {kind} ({exc})") from None


_INT_TYPES = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Enumeration")


@dataclass(frozen=True)
class VariableMap:
    """The FMU variables a plant uses: inputs, outputs and states (Real/Float64), parameters (any number type)."""

    vars: dict
    real_type: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    states: tuple[str, ...]
    parameters: dict


def _check_real(md: Any, vars_: dict, names: list[str], *, what: str, real_type: str) -> None:
    model = md.modelName
    for n in names:
        v = vars_.get(n)
        if v is None:
            raise PlantError(f"FMU {model} has no variable named {n!r} (for {what})")
        if v.type != real_type:
            raise PlantError(f"FMU {model}: variable {n!r} is {v.type}, but {what} must be {real_type} variables")


def map_variables(
    md: Any, *, inputs: Any = None, outputs: Any = None, states: Any = None, parameters: Mapping[str, Any] | None = None
) -> VariableMap:
    """Check a plant's variable mapping against the model description; one :class:`PlantError` line when
    a name is unknown, a variable has the wrong type or causality, or the plant would have no input or output.

    Inputs must be ``causality="input"`` variables; outputs and states any Real (Float64) variable; by
    default the declared inputs/outputs and the continuous states (ModelStructure/Derivatives).
    """
    real_type = "Float64" if md.fmiVersion == "3.0" else "Real"
    vars_ = {v.name: v for v in md.modelVariables}
    for what, names in (("inputs", inputs), ("outputs", outputs), ("states", states)):
        if names is not None and (not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names)):
            raise PlantError(f"plant fmu: {what} must be a list of variable names")
    declared = lambda c: [v.name for v in md.modelVariables if v.causality == c and v.type == real_type]  # noqa: E731
    in_names = list(inputs) if inputs is not None else declared("input")
    out_names = list(outputs) if outputs is not None else declared("output")
    if not in_names:
        raise PlantError(f"FMU {md.modelName} has no {real_type} input to drive (declare one, or map inputs = [...])")
    if not out_names:
        raise PlantError(f"FMU {md.modelName} has no {real_type} output to sample (map outputs = [...])")
    _check_real(md, vars_, in_names, what="inputs", real_type=real_type)
    _check_real(md, vars_, out_names, what="outputs", real_type=real_type)
    not_inputs = [n for n in in_names if vars_[n].causality != "input"]
    if not_inputs:
        raise PlantError(
            f"FMU {md.modelName}: {', '.join(not_inputs)} is not an input (causality "
            f"{vars_[not_inputs[0]].causality}); set it through parameters"
        )
    if states is None:
        states = [d.variable.derivative.name for d in md.derivatives] if md.derivatives else out_names
    _check_real(md, vars_, list(states), what="states", real_type=real_type)
    params = {}
    for key, value in (parameters or {}).items():
        v = vars_.get(key)
        if v is None:
            raise PlantError(f"FMU {md.modelName} has no variable {key!r} to set")
        params[key] = _typed_value(md, v, value)
    return VariableMap(
        vars=vars_,
        real_type=real_type,
        inputs=tuple(in_names),
        outputs=tuple(out_names),
        states=tuple(states),
        parameters=params,
    )


def _typed_value(md: Any, v: Any, value: Any) -> Any:
    """``value`` as the variable's type (a bool for Boolean, an int for Integer), or one PlantError line."""
    ok_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if v.type == "Boolean":
        if isinstance(value, bool):
            return value
    elif v.type in _INT_TYPES:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif v.type in ("Real", "Float64", "Float32"):
        if ok_number:
            return float(value)
    else:
        raise PlantError(f"FMU {md.modelName}: variable {v.name!r} is {v.type}; the bridge sets numbers and booleans")
    raise PlantError(f"FMU {md.modelName}: variable {v.name!r} is {v.type}; {value!r} is not a value of that type")


def set_values(fmu: Any, md: Any, values: Mapping[str, Any], *, vars_: dict) -> None:
    """Set typed values (:func:`_typed_value`) through the matching fmpy setter, grouped by type."""
    v3 = md.fmiVersion == "3.0"
    groups: dict[str, tuple[list[int], list[Any]]] = {}
    for key, value in values.items():
        t = vars_[key].type
        kind = "bool" if t == "Boolean" else "int" if t in _INT_TYPES else "real"
        refs, vals = groups.setdefault(kind, ([], []))
        refs.append(vars_[key].valueReference)
        vals.append(value)
    setters = {
        "real": fmu.setFloat64 if v3 else fmu.setReal,
        "int": fmu.setInt32 if v3 else fmu.setInteger,
        "bool": fmu.setBoolean,
    }
    for kind, (refs, vals) in groups.items():
        setters[kind](refs, vals)


def open_binary(path: Path, md: Any, fmpy_class: Any, model_identifier: str) -> tuple[Any, str, bool]:
    """Load an FMU's binary as the fmpy class ``fmpy_class`` (FMU2Slave, FMU2Model, FMU3Slave).

    Returns the instance, the unzip folder and whether that folder is ours to remove (``path`` was an archive,
    not an unzipped FMU). A binary that does not load is a PlantError, and leaves no folder behind.
    """
    from fmpy import extract

    own = path.is_file()
    unzip = extract(str(path)) if own else str(path)
    try:
        fmu = fmpy_class(guid=md.guid, unzipDirectory=unzip, modelIdentifier=model_identifier, instanceName="plant")
    except Exception as exc:
        if own:
            shutil.rmtree(unzip, ignore_errors=True)
        raise PlantError(f"FMU {path}: cannot load its binary ({exc})") from None
    return fmu, unzip, own


class FmuPlant(Plant):
    """A Co-Simulation FMU as a plant.

    Parameters
    ----------
    path : Path
        The ``.fmu`` file (or extracted folder).
    inputs, outputs : list of str, optional
        FMU variable names mapped to the artifact's inputs/outputs (default: the FMU's declared
        inputs and outputs, in model-description order).
    parameters : mapping, optional
        Start values for parameters (or any settable real) applied on every reset.
    states : list of str, optional
        Variables reported as the plant state (default: continuous states from the model
        structure, else the outputs).
    """

    def __init__(
        self,
        *,
        path: Path,
        inputs: Any = None,
        outputs: Any = None,
        parameters: Mapping[str, float] | None = None,
        states: Any = None,
    ) -> None:
        self.path = Path(path)
        md = read_description(self.path)
        self.md = md
        self.name = f"fmu:{md.modelName}"
        if md.fmiVersion not in ("2.0", "3.0"):
            raise PlantError(
                f"FMU {self.path} is FMI {md.fmiVersion}; the bridge runs FMI 2.0 and 3.0 Co-Simulation FMUs"
            )
        self.v3 = md.fmiVersion == "3.0"
        if self.v3:
            from ctypes import byref

            from fmpy.fmi3 import FMU3Slave as Slave
            from fmpy.fmi3 import fmi3Boolean
            from fmpy.fmi3 import fmi3Float64 as Real
            from fmpy.fmi3 import fmi3ValueReference as ValueReference

            self._flags = [fmi3Boolean() for _ in range(3)]
            self._last_time = Real()
            self._step_refs = tuple(byref(f) for f in self._flags) + (byref(self._last_time),)
        else:
            from fmpy.fmi2 import FMU2Slave as Slave
            from fmpy.fmi2 import fmi2Real as Real
            from fmpy.fmi2 import fmi2ValueReference as ValueReference

        if md.coSimulation is None:
            raise PlantError(f"FMU {self.path} has no Co-Simulation interface (FmuModelExchangePlant runs it)")
        mapping = map_variables(md, inputs=inputs, outputs=outputs, states=states, parameters=parameters)
        self.vars, self.real_type = mapping.vars, mapping.real_type
        in_names, out_names, states = mapping.inputs, mapping.outputs, mapping.states
        self.input_names, self.output_names, self.state_names = in_names, out_names, states
        self.parameters = mapping.parameters
        self.can_snapshot = bool(md.coSimulation.canGetAndSetFMUstate)
        self.fmu, self._unzip, self._own_unzip = open_binary(self.path, md, Slave, md.coSimulation.modelIdentifier)
        self._instantiated = False
        self._messages: list[str] = []
        self._callbacks = None if self.v3 else _fmi2_callbacks(id(self), self._messages)
        vr = lambda names: (ValueReference * len(names))(*(self.vars[n].valueReference for n in names))  # noqa: E731
        self._vr_in, self._vr_out, self._vr_state = vr(in_names), vr(out_names), vr(list(states))
        self._val_in = (Real * len(in_names))()
        self._val_out = (Real * len(out_names))()
        self._val_state = (Real * len(states))()
        self._out_np = np.frombuffer(self._val_out, dtype=np.float64)
        self._in_np = np.frombuffer(self._val_in, dtype=np.float64)
        self._n_in, self._n_out = len(in_names), len(out_names)
        self.time = 0.0
        self.reset(initial={})

    def _cleanup_unzip(self) -> None:
        if self._own_unzip and self._unzip:
            shutil.rmtree(self._unzip, ignore_errors=True)
        self._unzip = None

    def _reason(self, exc: Exception) -> str:
        """The FMU's last logged message for a failed call (else the exception), and forget the log."""
        reason = self._messages[-1] if self._messages else str(exc)
        self._messages.clear()
        return reason

    def _call(self, what: str, fn: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except Exception as exc:
            raise PlantError(f"FMU {self.md.modelName}: {what} failed ({self._reason(exc)})") from None

    def reset(self, *, initial: Mapping[str, float]) -> None:
        fmu = self.fmu
        if self._instantiated:
            self._call("terminate", fmu.terminate)
            self._call("reset", fmu.reset)
        else:
            if self.v3:
                self._call("instantiate", fmu.instantiate)
            else:
                self._call("instantiate", fmu.instantiate, False, self._callbacks)
            self._instantiated = True
        if self.v3:
            self._call("enterInitializationMode", fmu.enterInitializationMode, None, 0.0)
        else:
            self._call("setupExperiment", fmu.setupExperiment, None, 0.0)
            self._call("enterInitializationMode", fmu.enterInitializationMode)
        values = dict(self.parameters)
        for key, value in initial.items():
            if key not in self.vars or self.vars[key].type != self.real_type:
                raise PlantError(
                    f"FMU {self.md.modelName} has no {self.real_type} variable {key!r} for the initial state"
                )
            values[key] = float(value)
        if values:
            self._call("set", set_values, fmu, self.md, values, vars_=self.vars)
        self._call("exitInitializationMode", fmu.exitInitializationMode)
        if self.v3:
            self._call("enterStepMode", fmu.fmi3EnterStepMode, fmu.component)
        self.time = 0.0
        self._get(self._vr_out, self._n_out, self._val_out)

    def _get(self, vr: Any, n: int, out: Any) -> None:
        fmu = self.fmu
        if self.v3:
            self._call("getFloat64", fmu.fmi3GetFloat64, fmu.component, vr, n, out, n)
        else:
            self._call("getReal", fmu.fmi2GetReal, fmu.component, vr, n, out)

    def outputs(self) -> np.ndarray:
        return self._out_np.copy()

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        fmu = self.fmu
        self._in_np[:] = u
        try:
            if self.v3:
                fmu.fmi3SetFloat64(fmu.component, self._vr_in, self._n_in, self._val_in, self._n_in)
                fmu.fmi3DoStep(fmu.component, self.time, dt, True, *self._step_refs)
                fmu.fmi3GetFloat64(fmu.component, self._vr_out, self._n_out, self._val_out, self._n_out)
            else:
                fmu.fmi2SetReal(fmu.component, self._vr_in, self._n_in, self._val_in)
                fmu.fmi2DoStep(fmu.component, self.time, dt, 1)
                fmu.fmi2GetReal(fmu.component, self._vr_out, self._n_out, self._val_out)
        except Exception as exc:
            raise PlantError(
                f"FMU {self.md.modelName}: step at t={self.time:.6g} failed ({self._reason(exc)})"
            ) from None
        self.time += dt

    def state(self) -> np.ndarray:
        self._get(self._vr_state, len(self.state_names), self._val_state)
        return np.array(self._val_state[:], dtype=float)

    def save_state(self) -> Any:
        if not self.can_snapshot:
            raise PlantError(f"FMU {self.md.modelName} cannot get/set its state (canGetAndSetFMUstate=false)")
        getter = self.fmu.getFMUState if self.v3 else self.fmu.getFMUstate
        return (self._call("getFMUstate", getter), self.time, self._out_np.copy())

    def restore_state(self, snapshot: Any) -> None:
        state, t, out = snapshot
        self._call("setFMUstate", self.fmu.setFMUState if self.v3 else self.fmu.setFMUstate, state)
        self.time = t
        self._out_np[:] = out

    def close(self) -> None:
        fmu = getattr(self, "fmu", None)
        if fmu is not None:
            try:
                if self._instantiated:
                    fmu.terminate()
                    fmu.freeInstance()  # FMI 3.0: also frees the library
                if not (self.v3 and self._instantiated):
                    fmu.freeLibrary()
            except Exception:  # closing is best effort; a broken FMU already reported its error
                log.debug("FMU close failed", exc_info=True)
            self.fmu = None
        _FMI2_SINKS.pop(id(self), None)
        self._cleanup_unzip()


@PLANTS.register("fmu")
def _fmu_factory(config: Mapping[str, Any], *, base_dir: Path | None = None, **_context: Any) -> Plant:
    cfg = take_keys(
        config,
        allowed={"kind", "fmu", "path", "inputs", "outputs", "parameters", "states", "interface", "rtol", "max_step"},
        where="plant fmu",
        error=PlantError,
    )
    path = resolve_fmu(fmu=cfg.get("fmu"), path=cfg.get("path"), base_dir=base_dir)
    interface = cfg.get("interface", "auto")
    if interface not in ("auto", "cs", "me"):
        raise PlantError(f"plant fmu: interface must be auto, cs or me, not {interface!r}")
    md = read_description(path)
    if interface == "auto":
        interface = "cs" if md.coSimulation is not None else "me"
    common = dict(
        path=path,
        inputs=cfg.get("inputs"),
        outputs=cfg.get("outputs"),
        parameters=cfg.get("parameters"),
        states=cfg.get("states"),
    )
    if interface == "me":
        from .fmu_me import FmuModelExchangePlant

        solver = {k: float(cfg[k]) for k in ("rtol", "max_step") if k in cfg}
        return FmuModelExchangePlant(**common, **solver)
    if "rtol" in cfg or "max_step" in cfg:
        raise PlantError('plant fmu: rtol and max_step set fmpy\'s solver, which runs only with interface = "me"')
    if md.coSimulation is None:
        raise PlantError(f'FMU {path} has no Co-Simulation interface (interface = "me" runs its Model Exchange)')
    return FmuPlant(**common)
