"""A plant simulated by a Co-Simulation FMU through fmpy's low-level slave loop: FMI 2.0
(``FMU2Slave``) or FMI 3.0 (``FMU3Slave``, Float64 variables).

Per step the bridge calls the raw ``fmi2SetReal`` / ``fmi2DoStep`` / ``fmi2GetReal`` (FMI 3.0:
``fmi3SetFloat64`` / ``fmi3DoStep`` / ``fmi3GetFloat64``) with ctypes arrays built once
(FIELD-NOTES: ~2.5 us per step instead of ~4.8 us through the list wrappers). Snapshots use
``fmi2GetFMUstate`` / ``fmi3GetFMUState`` when the FMU can. An FMI 2.0 FMU's log goes to
:mod:`logging`, and a failed call's :class:`PlantError` carries the FMU's last logged message.

Inside :func:`reused_instances` (a campaign's worker runs its runs there), a closed plant keeps its FMPy instance
(the unzipped binary, the loaded library, the instantiated FMU) for the next plant of the same interface, FMU file and
variables opened in this process (:func:`opened`, for :class:`FmuPlant` and
:class:`.fmu_me.FmuModelExchangePlant` alike), which sets its parameters and resets it (``fmi2Reset`` /
``fmi3Reset``, then the experiment set up again, as every run's start does): FMPy unzips an FMU per instance and
instances leak memory (fmpy issues), so a campaign opens one instance per (FMU, worker) and use at a time, not one per
run. A plant whose FMU call failed is freed, never reused.
"""

from __future__ import annotations

import atexit
import contextlib
import contextvars
import json
import logging
import shutil
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from .base import Plant
from .fmi import fmi2_callbacks, forget_log, map_variables, open_binary, read_description, set_values

log = logging.getLogger(__name__)

_REUSE: contextvars.ContextVar[bool] = contextvars.ContextVar("gainlink_fmu_reuse", default=False)
_IDLE: dict[str, list[Any]] = {}  # closed plants kept for reuse, by interface, FMU file and variables


@contextlib.contextmanager
def reused_instances() -> Iterator[None]:
    """Within: a closed FMU plant is kept for the next :func:`opened` of the same interface, FMU and variables
    in this process (see the module docstring); the kept instances outlive the block (freed at exit)."""
    token = _REUSE.set(True)
    try:
        yield
    finally:
        _REUSE.reset(token)


def idle_instances() -> dict[str, list[Any]]:
    """The plants kept for reuse in this process (Co-Simulation and Model Exchange), by FMU file and variables."""
    return {k: list(v) for k, v in _IDLE.items()}


def taken_idle(key: str | None) -> Any:
    """An idle plant kept under ``key`` (:func:`reuse_key`), taken out of the pool; None when there is none or
    when not inside :func:`reused_instances` (``key`` None)."""
    idle = _IDLE.get(key) if key is not None else None
    return idle.pop() if idle else None


def kept_idle(plant: Any, *, broken: bool) -> bool:
    """Keep ``plant`` (closed by its run) for the next :func:`taken_idle` of its key, inside
    :func:`reused_instances` and unless a call of it failed (``broken``); False when it is to be freed."""
    key = getattr(plant, "_reuse_key", None)
    if key is None or not _REUSE.get() or broken:
        return False
    if plant not in _IDLE.setdefault(key, []):
        _IDLE[key].append(plant)
    return True


@atexit.register
def _free_idle() -> None:
    for plants in _IDLE.values():
        for plant in plants:
            plant._free()
    _IDLE.clear()


def opened(cls: Any, args: dict, settings: dict) -> Any:
    """A plant of ``cls`` (an FMU plant class) for ``args`` (its ``path``, ``inputs``, ``outputs``, ``parameters``,
    ``states``) and ``settings`` (its other constructor arguments): inside :func:`reused_instances` an idle one of the
    same interface, FMU file and variables, given its parameters and renewed (``renew(settings)``: reset), when one
    was closed; else a new one."""
    key = reuse_key(cls.interface, args["path"], args["inputs"], args["outputs"], args["states"])
    plant = taken_idle(key)
    if plant is None:
        plant = cls(**args, **settings)
    else:
        try:
            plant.parameters = map_variables(plant.md, **{k: v for k, v in args.items() if k != "path"}).parameters
            plant.renew(settings)
        except BaseException:  # a refused parameter or setting, a failed reset: the instance is freed, not lost
            plant._free()
            raise
    plant._reuse_key = key
    return plant


def reuse_key(interface: str, path: Path, inputs: Any, outputs: Any, states: Any) -> str | None:
    """What a kept plant must share with the next one to serve it (its interface, FMU file and variables); None
    outside :func:`reused_instances` (nothing is kept)."""
    if not _REUSE.get():
        return None
    stat = Path(path).stat()
    where = [interface, str(Path(path).resolve()), stat.st_size, stat.st_mtime_ns, inputs, outputs, states]
    return json.dumps(where, default=str)


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

    interface = "cs"

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
        self._callbacks = None if self.v3 else fmi2_callbacks(id(self), self._messages)
        vr = lambda names: (ValueReference * len(names))(*(self.vars[n].valueReference for n in names))  # noqa: E731
        self._vr_in, self._vr_out, self._vr_state = vr(in_names), vr(out_names), vr(list(states))
        self._val_in = (Real * len(in_names))()
        self._val_out = (Real * len(out_names))()
        self._val_state = (Real * len(states))()
        self._out_np = np.frombuffer(self._val_out, dtype=np.float64)
        self._in_np = np.frombuffer(self._val_in, dtype=np.float64)
        self._n_in, self._n_out = len(in_names), len(out_names)
        self.time = 0.0
        self._reuse_key: str | None = None
        self._broken = False
        self.reset(initial={})

    def renew(self, settings: dict) -> None:
        """Serve a new run (:func:`opened`, which set its parameters): the instance reset."""
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
            self._broken = True
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
            self._broken = True
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
        """Free the FMU; inside :func:`reused_instances`, keep it for the next :meth:`open` of the same FMU instead
        (unless a call of it failed)."""
        if not kept_idle(self, broken=self._broken or self.fmu is None):
            self._free()

    def _free(self) -> None:
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
        forget_log(id(self))
        self._cleanup_unzip()
