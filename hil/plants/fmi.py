"""Reading an FMU, shared by its Co-Simulation (:mod:`.fmu`) and Model Exchange (:mod:`.fmu_me`) plants,
linearisation and the interface check: the file a plant config names, its model description, the variables a
plant maps, its binary, and the FMU's log (FMI 2.0 callbacks; FMI 3.0 log messages).
"""

from __future__ import annotations

import hashlib
import logging
import re
import shutil
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gainlink.errors import PlantError

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
_SINKS: dict[int, list[str]] = {}
_FMI2_DISPATCH: Any = None


def _fmi2_dispatch(env: Any, instance: Any, status: int, category: Any, message: bytes) -> None:
    sink = _SINKS.get(env or 0)
    if sink is None:  # an FMU instantiated with fmpy's default callbacks: print as fmpy does
        from fmpy.fmi1 import printLogMessage

        printLogMessage(env, instance, status, category, message)
        return
    text = message.decode("utf-8", errors="replace")
    # Errors make the FMI call fail and reach the PlantError line; warnings are only logged.
    log.log(logging.WARNING if status == 1 else logging.DEBUG, "FMU: %s", text)
    if status >= 1:  # fmi2Warning and worse
        sink[:] = [text]  # the latest is the reason of a failed call


def fmi2_callbacks(key: int, messages: list[str]) -> Any:
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
    _SINKS[key] = messages
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


def forget_log(key: int) -> None:
    """Stop collecting the log of the plant ``key`` (its instance is freed)."""
    _SINKS.pop(key, None)


def fmi3_logger(messages: list[str]) -> Any:
    """An FMI 3.0 log-message callback that keeps the FMU's warnings and errors in ``messages`` (the latest is
    the reason of a failed call) and sends every message to :mod:`logging`."""

    def log_message(env: Any, status: int, category: Any, message: bytes) -> None:
        text = message.decode("utf-8", errors="replace") if isinstance(message, bytes) else str(message)
        log.log(logging.WARNING if status == 1 else logging.DEBUG, "FMU: %s", text)
        if status >= 1:
            messages[:] = [text]

    return log_message


def fmu_sha256(path: Path) -> str:
    """sha256 of an ``.fmu`` archive's bytes, or of an unzipped FMU folder's files (relative names and bytes)."""
    h = hashlib.sha256()
    path = Path(path)
    if path.is_file():
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest()
    for p in sorted(q for q in path.rglob("*") if q.is_file()):
        h.update(p.relative_to(path).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def signal_name(name: str) -> str:
    """An FMU variable's name as a spec's signal name (``damper.s_rel`` -> ``damper_s_rel``)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return s if re.match(r"[A-Za-z_]", s) else f"s_{s}"


def settable_at_start(md: Any, name: str) -> bool:
    """Whether the FMU takes a start value for ``name`` in initialisation mode (a parameter, an input, or a
    variable with ``initial`` exact or approx; a calculated one is the FMU's to compute)."""
    v = next((v for v in md.modelVariables if v.name == name), None)
    return v is not None and (v.causality in ("parameter", "input") or v.initial in ("exact", "approx"))
