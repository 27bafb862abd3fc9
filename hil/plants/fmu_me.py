"""A plant simulated by an FMI 2.0 or 3.0 Model Exchange FMU, integrated by fmpy's own CVode solver.

This is the machinery of fmpy's ``simulateME`` (``fmpy.sundials.CVodeSolver`` over the FMU's
``getContinuousStates`` / ``getDerivatives`` / ``getEventIndicators``, event iteration with
``newDiscreteStates``), driven one bridge step at a time instead of over a whole experiment: the
input is held over each step (set once; the solver is re-initialised at the step, where the held
input jumps), time events and state events found by CVode's root finding end an integration
segment, the FMU updates its discrete states and CVode restarts from there.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from .base import Plant
from .fmi import map_variables, read_description
from .fmi_me import ModelExchange, check_model_exchange
from .fmu import kept_idle


class _HeldInput:
    """fmpy's solvers call ``input.apply(t)``; the bridge's input is set once per step and held."""

    def apply(self, time: float, continuous: bool = True, discrete: bool = True, after_event: bool = False) -> None:
        return None


#: CVode's relative tolerance unless the plant table sets ``rtol``
RTOL = 1e-8


class FmuModelExchangePlant(Plant):
    """An FMI 2.0 or 3.0 Model Exchange FMU as a plant (fmpy's CVode integrates it).

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

    interface = "me"

    def __init__(
        self,
        *,
        path: Path,
        inputs: Any = None,
        outputs: Any = None,
        parameters: Mapping[str, Any] | None = None,
        states: Any = None,
        rtol: float = RTOL,
        max_step: float | None = None,
    ) -> None:
        self.path = Path(path)
        md = read_description(self.path)
        self.md = md
        check_model_exchange(self.path, md)
        self.rtol, self.max_step = _solver_settings(rtol, max_step)
        self.name = f"fmu:{md.modelName}"
        mapping = map_variables(md, inputs=inputs, outputs=outputs, states=states, parameters=parameters)
        self.vars, self.real_type = mapping.vars, mapping.real_type
        self.input_names, self.output_names, self.state_names = mapping.inputs, mapping.outputs, mapping.states
        self.parameters = mapping.parameters
        self.can_snapshot = bool(md.modelExchange.canGetAndSetFMUstate)
        self._vr_in = [self.vars[n].valueReference for n in self.input_names]
        self._vr_out = [self.vars[n].valueReference for n in self.output_names]
        self._vr_state = [self.vars[n].valueReference for n in self.state_names]
        self._messages: list[str] = []
        self.me = ModelExchange(self.path, md, messages=self._messages, key=id(self))
        self.solver: Any = None
        self.time = 0.0
        self._out = np.zeros(len(self._vr_out))
        self._reuse_key: str | None = None
        self._broken = False
        self.reset(initial={})

    def renew(self, settings: dict) -> None:
        """Serve a new run (:func:`~.fmu.opened`, which set its parameters): its solver ``settings``, the instance
        reset and a new CVode solver made."""
        self.rtol, self.max_step = _solver_settings(settings.get("rtol", RTOL), settings.get("max_step"))
        self.reset(initial={})

    def _call(self, what: str, fn: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except PlantError:
            self._broken = True
            raise
        except Exception as exc:
            self._broken = True
            raise PlantError(f"FMU {self.md.modelName}: {what} failed ({self._reason(exc)})") from None

    def _reason(self, exc: Exception) -> str:
        """The FMU's last logged message for a failed call (else the exception), and forget the log."""
        reason = self._messages[-1] if self._messages else str(exc)
        self._messages.clear()
        return reason

    def _event_update(self) -> None:
        """Iterate the discrete states to a fixed point (fmpy's simulateME does the same)."""
        needed, terminate, defined, next_time = True, False, False, 0.0
        while needed and not terminate:
            needed, terminate, defined, next_time = self.me.update_discrete()
        if terminate:
            raise PlantError(f"FMU {self.md.modelName} asked to terminate at t={self.time:.6g}")
        self._next_event = next_time if defined else math.inf

    def reset(self, *, initial: Mapping[str, float]) -> None:
        values = dict(self.parameters)
        for key, value in initial.items():
            if key not in self.vars or self.vars[key].type != self.real_type:
                raise PlantError(
                    f"FMU {self.md.modelName} has no {self.real_type} variable {key!r} for the initial state"
                )
            values[key] = float(value)
        self._call("initialisation", self.me.initialise, values, vars_=self.vars)
        self.time = 0.0
        self._call("initial event update", self._event_update)
        self._call("enterContinuousTimeMode", self.me.enter_continuous)
        self.solver = self._new_solver()
        self._out = np.array(self._call("get outputs", self.me.get_real, self._vr_out))

    def _new_solver(self) -> Any:
        from fmpy.sundials import CVodeSolver

        me = self.me
        return CVodeSolver(
            nx=me.nx,
            nz=me.nz,
            get_x=me.get_x,
            set_x=me.set_x,
            get_dx=me.get_dx,
            get_z=me.get_z,
            input=_HeldInput(),
            get_nominals=me.get_nominals,
            set_time=me.set_time,
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
            self._broken = True
            raise
        except Exception as exc:  # CVode's RuntimeError, fmpy's FMICallException
            self._broken = True
            raise PlantError(
                f"FMU {self.md.modelName}: step at t={self.time:.6g} failed ({self._reason(exc)})"
            ) from None

    def _integrate(self, u: np.ndarray, dt: float) -> None:
        me, solver = self.me, self.solver
        me.set_real(self._vr_in, list(u))
        solver.reset(self.time)  # the held input jumped: restart CVode's history here
        t, t_end = self.time, self.time + dt
        needs_step_call = bool(self.md.modelExchange.needsCompletedIntegratorStep)
        while t_end - t > 1e-12 * max(1.0, abs(t_end)):
            target = min(t_end, self._next_event)
            state_event, _roots, t = solver.step(t, target)
            me.set_time(t)
            step_event = False
            if needs_step_call:
                step_event, terminate = me.completed_step()
                if terminate:
                    raise PlantError(f"FMU {self.md.modelName} asked to terminate at t={t:.6g}")
            time_event = math.isclose(t, self._next_event, rel_tol=0, abs_tol=1e-12 * max(1.0, abs(t)))
            if state_event or step_event or time_event:
                me.enter_event()
                self.time = t
                self._event_update()
                me.enter_continuous()
                solver.reset(t)
        self.time = t_end
        self._out = np.array(me.get_real(self._vr_out))
        if not np.all(np.isfinite(self._out)):
            raise PlantError(f"FMU {self.md.modelName}: outputs became non-finite at t={t_end:.6g}")

    def state(self) -> np.ndarray:
        return np.array(self._call("get states", self.me.get_real, self._vr_state), dtype=float)

    def save_state(self) -> Any:
        if not self.can_snapshot:
            raise PlantError(f"FMU {self.md.modelName} cannot get/set its state (canGetAndSetFMUstate=false)")
        return (self._call("getFMUstate", self.me.get_state), self.time, self._out.copy(), self._next_event)

    def restore_state(self, snapshot: Any) -> None:
        state, t, out, next_event = snapshot
        self._call("setFMUstate", self.me.set_state, state)
        self.time, self._out, self._next_event = t, out.copy(), next_event
        self.solver.reset(t)

    def close(self) -> None:
        """Free the FMU; inside :func:`~.fmu.reused_instances`, keep its instance for the next :meth:`open` of the
        same FMU instead (unless a call of it failed). Its CVode solver is freed either way."""
        self.solver = None  # CVode's memory is freed before the FMU that its callbacks reach
        if not kept_idle(self, broken=self._broken or getattr(self, "me", None) is None):
            self._free()

    def _free(self) -> None:
        self.solver = None
        if getattr(self, "me", None) is not None:
            self.me.close()
            self.me = None


def _solver_settings(rtol: float, max_step: float | None) -> tuple[float, float | None]:
    """CVode's relative tolerance and largest step, checked: one :class:`PlantError` line for a bad one."""
    if not (rtol > 0 and math.isfinite(rtol)):
        raise PlantError("plant fmu: rtol must be a positive number")
    if max_step is not None and not max_step > 0:
        raise PlantError("plant fmu: max_step must be positive")
    return float(rtol), max_step
