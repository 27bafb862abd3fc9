"""A plant simulated by an FMI 2.0 Model Exchange FMU, integrated by fmpy's own CVode solver.

This is the machinery of fmpy's ``simulateME`` (``fmpy.sundials.CVodeSolver`` over the FMU's
``getContinuousStates`` / ``getDerivatives`` / ``getEventIndicators``, event iteration with
``newDiscreteStates``), driven one bridge step at a time instead of over a whole experiment: the
input is held over each step (set once; the solver is re-initialised at the step, where the held
input jumps), time events and state events found by CVode's root finding end an integration
segment, the FMU updates its discrete states and CVode restarts from there.
"""

from __future__ import annotations

import logging
import math
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from .base import Plant
from .fmu import _FMI2_SINKS, _fmi2_callbacks, map_variables, open_binary, read_description, set_values

log = logging.getLogger(__name__)


class _HeldInput:
    """fmpy's solvers call ``input.apply(t)``; the bridge's input is set once per step and held."""

    def apply(self, time: float, continuous: bool = True, discrete: bool = True, after_event: bool = False) -> None:
        return None


class FmuModelExchangePlant(Plant):
    """An FMI 2.0 Model Exchange FMU as a plant (fmpy's CVode integrates it).

    Parameters
    ----------
    path : Path
        The ``.fmu`` file (or extracted folder).
    inputs, outputs, states, parameters
        As :class:`gainlink.hil.plants.fmu.FmuPlant`.
    rtol : float
        CVode's relative tolerance (absolute: ``rtol`` times each state's nominal value, as fmpy does).
    max_step : float, optional
        CVode's largest internal step (default: unbounded within a bridge step).
    """

    def __init__(
        self,
        *,
        path: Path,
        inputs: Any = None,
        outputs: Any = None,
        parameters: Mapping[str, Any] | None = None,
        states: Any = None,
        rtol: float = 1e-8,
        max_step: float | None = None,
    ) -> None:
        from fmpy.fmi2 import FMU2Model

        self.path = Path(path)
        md = read_description(self.path)
        self.md = md
        if md.fmiVersion != "2.0" or md.modelExchange is None:
            raise PlantError(
                f"FMU {self.path}: the Model Exchange plant runs FMI 2.0 Model Exchange FMUs "
                f"(this one is FMI {md.fmiVersion}{'' if md.modelExchange else ' without Model Exchange'})"
            )
        if not (rtol > 0 and math.isfinite(rtol)):
            raise PlantError("plant fmu: rtol must be a positive number")
        if max_step is not None and not max_step > 0:
            raise PlantError("plant fmu: max_step must be positive")
        self.name = f"fmu:{md.modelName}"
        mapping = map_variables(md, inputs=inputs, outputs=outputs, states=states, parameters=parameters)
        self.vars = mapping.vars
        self.input_names, self.output_names, self.state_names = mapping.inputs, mapping.outputs, mapping.states
        self.parameters = mapping.parameters
        self.rtol, self.max_step = float(rtol), max_step
        self.can_snapshot = bool(md.modelExchange.canGetAndSetFMUstate)
        self._vr_in = [self.vars[n].valueReference for n in self.input_names]
        self._vr_out = [self.vars[n].valueReference for n in self.output_names]
        self._vr_state = [self.vars[n].valueReference for n in self.state_names]
        self.fmu, self._unzip, self._own_unzip = open_binary(self.path, md, FMU2Model, md.modelExchange.modelIdentifier)
        self._messages: list[str] = []
        self._callbacks = _fmi2_callbacks(id(self), self._messages)
        self._instantiated = False
        self.solver: Any = None
        self.time = 0.0
        self._out = np.zeros(len(self._vr_out))
        self.reset(initial={})

    def _cleanup_unzip(self) -> None:
        if self._own_unzip and self._unzip:
            shutil.rmtree(self._unzip, ignore_errors=True)
        self._unzip = None

    def _call(self, what: str, fn: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except Exception as exc:
            reason = self._messages[-1] if self._messages else str(exc)
            self._messages.clear()
            raise PlantError(f"FMU {self.md.modelName}: {what} failed ({reason})") from None

    def _event_update(self) -> None:
        """Iterate the discrete states to a fixed point (fmpy's simulateME does the same)."""
        fmu = self.fmu
        needed, terminate = True, False
        while needed and not terminate:
            needed, terminate, _, _, defined, next_time = fmu.newDiscreteStates()
        if terminate:
            raise PlantError(f"FMU {self.md.modelName} asked to terminate at t={self.time:.6g}")
        self._next_event = next_time if defined else math.inf

    def reset(self, *, initial: Mapping[str, float]) -> None:
        fmu = self.fmu
        if self._instantiated:
            self._call("terminate", fmu.terminate)
            self._call("reset", fmu.reset)
        else:
            self._call("instantiate", fmu.instantiate, False, self._callbacks)
            self._instantiated = True
        self._call("setupExperiment", fmu.setupExperiment, None, 0.0)
        self._call("enterInitializationMode", fmu.enterInitializationMode)
        values = dict(self.parameters)
        for key, value in initial.items():
            if key not in self.vars or self.vars[key].type != "Real":
                raise PlantError(f"FMU {self.md.modelName} has no Real variable {key!r} for the initial state")
            values[key] = float(value)
        if values:
            self._call("set", set_values, fmu, self.md, values, vars_=self.vars)
        self._call("exitInitializationMode", fmu.exitInitializationMode)
        self.time = 0.0
        self._call("initial event update", self._event_update)
        self._call("enterContinuousTimeMode", fmu.enterContinuousTimeMode)
        self.solver = self._new_solver()
        self._out = np.array(self._call("getReal", fmu.getReal, self._vr_out))

    def _new_solver(self) -> Any:
        from fmpy.sundials import CVodeSolver

        fmu, md = self.fmu, self.md
        return CVodeSolver(
            nx=md.numberOfContinuousStates,
            nz=md.numberOfEventIndicators,
            get_x=fmu.getContinuousStates,
            set_x=fmu.setContinuousStates,
            get_dx=fmu.getDerivatives,
            get_z=fmu.getEventIndicators,
            input=_HeldInput(),
            get_nominals=fmu.getNominalsOfContinuousStates,
            set_time=fmu.setTime,
            startTime=self.time,
            maxStep=self.max_step or 1e300,
            relativeTolerance=self.rtol,
        )

    def outputs(self) -> np.ndarray:
        return self._out.copy()

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        try:
            self._integrate(np.asarray(u, float), dt)
        except PlantError:
            raise
        except Exception as exc:  # CVode's RuntimeError, fmpy's FMICallException
            reason = self._messages[-1] if self._messages else str(exc)
            self._messages.clear()
            raise PlantError(f"FMU {self.md.modelName}: step at t={self.time:.6g} failed ({reason})") from None

    def _integrate(self, u: np.ndarray, dt: float) -> None:
        fmu, solver = self.fmu, self.solver
        fmu.setReal(self._vr_in, list(u))
        solver.reset(self.time)  # the held input jumped: restart CVode's history here
        t, t_end = self.time, self.time + dt
        needs_step_call = bool(self.md.modelExchange.needsCompletedIntegratorStep)
        while t_end - t > 1e-12 * max(1.0, abs(t_end)):
            target = min(t_end, self._next_event)
            state_event, _roots, t = solver.step(t, target)
            fmu.setTime(t)
            step_event = False
            if needs_step_call:
                step_event, terminate = fmu.completedIntegratorStep()
                if terminate:
                    raise PlantError(f"FMU {self.md.modelName} asked to terminate at t={t:.6g}")
            time_event = math.isclose(t, self._next_event, rel_tol=0, abs_tol=1e-12 * max(1.0, abs(t)))
            if state_event or step_event or time_event:
                fmu.enterEventMode()
                self.time = t
                self._event_update()
                fmu.enterContinuousTimeMode()
                solver.reset(t)
        self.time = t_end
        self._out = np.array(fmu.getReal(self._vr_out))
        if not np.all(np.isfinite(self._out)):
            raise PlantError(f"FMU {self.md.modelName}: outputs became non-finite at t={t_end:.6g}")

    def state(self) -> np.ndarray:
        return np.array(self._call("getReal", self.fmu.getReal, self._vr_state), dtype=float)

    def save_state(self) -> Any:
        if not self.can_snapshot:
            raise PlantError(f"FMU {self.md.modelName} cannot get/set its state (canGetAndSetFMUstate=false)")
        return (self._call("getFMUstate", self.fmu.getFMUstate), self.time, self._out.copy(), self._next_event)

    def restore_state(self, snapshot: Any) -> None:
        state, t, out, next_event = snapshot
        self._call("setFMUstate", self.fmu.setFMUstate, state)
        self.time, self._out, self._next_event = t, out.copy(), next_event
        self.solver.reset(t)

    def close(self) -> None:
        fmu = getattr(self, "fmu", None)
        if fmu is not None:
            self.solver = None  # CVode's memory is freed before the FMU that its callbacks reach
            try:
                if self._instantiated:
                    fmu.terminate()
                    fmu.freeInstance()
                fmu.freeLibrary()
            except Exception:  # best effort; a broken FMU already reported its error
                log.debug("FMU close failed", exc_info=True)
            self.fmu = None
        _FMI2_SINKS.pop(id(self), None)
        self._cleanup_unzip()
