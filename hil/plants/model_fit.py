"""How well a linearisation fits the FMU it came from, through the interface runs will use, at the spec's Ts.

``linearize`` writes a model; this checks it before anyone designs on it. The FMU (built as a run builds it:
the interface :func:`~.fmu_interface.choose_interface` picks at ``Ts``) and the discrete linear model are driven
by the same small input steps from the operating point (:mod:`.step_response`); per output the fit is the
NRMSE (RMS of the difference over every step response, relative to the largest range the FMU's responses
cover) and the final value of the response that moves it most (FMU, model, and their difference relative to
that range).

A fit is poor above :data:`POOR_FIT` (5 % NRMSE, or 5 % off at the final value): a model that far off changes
the designed loop's damping and steady state visibly (the model twin's threshold in run reports is the same 5 %).
The likely cause is named by repeating the steps at a quarter of the amplitude: an error that shrinks with the
amplitude (to less than half) is the plant's nonlinearity at that amplitude; one that does not is the FMU's own
solver or step (its Co-Simulation solver when that is what ran).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .fmu import FmuPlant
from .fmu_interface import InterfaceChoice
from .fmu_me import FmuModelExchangePlant
from .step_response import StepPlan, StepRuns, discretise, model_steps, plan_steps, run_steps

POOR_FIT = 0.05
SHRINK = 0.5  # at a quarter of the amplitude, an error from nonlinearity falls below this fraction


@dataclass(frozen=True)
class OutputFit:
    """One output's fit: ``nrmse``, and the final value of its largest step response in the FMU and the model
    with their difference relative to that response's range (``final_error``)."""

    nrmse: float
    final_fmu: float
    final_model: float
    final_error: float


@dataclass(frozen=True)
class ModelFit:
    """The fit per output (spec signal names), the experiment (``steps`` samples of ``Ts``, ``amplitudes`` per
    input), the interface it ran through and, for a poor fit, ``cause`` and the NRMSE at a quarter amplitude."""

    outputs: dict[str, OutputFit]
    amplitudes: dict[str, float]
    steps: int
    Ts: float
    interface: str
    cause: str | None = None
    worst_quarter: float | None = None

    @property
    def worst(self) -> float:
        """The largest of every output's NRMSE and final error."""
        return max((max(f.nrmse, f.final_error) for f in self.outputs.values()), default=0.0)

    @property
    def poor(self) -> bool:
        return not self.worst <= POOR_FIT

    def warning(self) -> str | None:
        """One line for a poor fit (None for a good one)."""
        if not self.poor:
            return None
        worst = max(self.outputs, key=lambda k: max(self.outputs[k].nrmse, self.outputs[k].final_error))
        f = self.outputs[worst]
        return (
            f"the linear model fits the FMU poorly at Ts = {self.Ts:g} s through "
            f"{'Co-Simulation' if self.interface == 'cs' else 'Model Exchange'} ({worst}: NRMSE {f.nrmse:.2g}, "
            f"final value off by {f.final_error:.2g} of the response); likely cause: {self.cause}"
        )

    def table(self) -> dict:
        """The spec's ``[linearization.fit]`` record: per output nrmse, final_fmu, final_model, final_error."""
        return {name: {k: float(v) for k, v in vars(f).items()} for name, f in self.outputs.items()}


def fit_model(
    lin: Any,
    *,
    choice: InterfaceChoice,
    plant_args: Mapping[str, Any],
    start: Mapping[str, float],
    Ts: float,
    names: tuple[list[str], list[str]],
) -> ModelFit:
    """The fit of ``lin`` (a :class:`~.linearize.Linearization`) to its FMU (see the module docstring).

    ``plant_args`` build the FMU plant (path, inputs, outputs, parameters); ``start`` holds the settable values
    that put it at the operating point; ``names`` are the spec's input and output names, for the record.
    """
    Ad, Bd = (lin.A, lin.B) if lin.Ts is not None else discretise(lin.A, lin.B, Ts)
    plan = plan_steps(Ad, Bd, lin.C, lin.D, u0=lin.u0, y0=lin.y0, Ts=Ts)
    model = model_steps(Ad, Bd, lin.C, lin.D, du=plan.amplitudes, steps=plan.steps)
    plant = _plant(choice.interface, plant_args)
    try:
        runs = run_steps(plant, plan, initial=_reset_values(plant, start))
        outputs = _fits(runs, model, names[1])
        fit = ModelFit(
            outputs=outputs,
            amplitudes=dict(zip(names[0], map(float, plan.amplitudes))),
            steps=plan.steps,
            Ts=float(Ts),
            interface=choice.interface,
        )
        return _diagnose(fit, plant, plan, model, start) if fit.poor else fit
    finally:
        plant.close()


def _plant(interface: str, plant_args: Mapping[str, Any]) -> Any:
    return FmuModelExchangePlant(**plant_args) if interface == "me" else FmuPlant(**plant_args)


def _reset_values(plant: Any, start: Mapping[str, float]) -> dict:
    return {k: v for k, v in start.items() if k not in plant.input_names}


def _fits(runs: StepRuns, model: np.ndarray, outputs: list[str]) -> dict[str, OutputFit]:
    """Per output: NRMSE over every step response, final value of the one that moves it most."""
    fits = {}
    for i, name in enumerate(outputs):
        fmu, lin = runs.steps[:, :, i], model[:, :, i]  # (m, K)
        ranges = np.ptp(fmu, axis=1)
        big = int(np.argmax(ranges))
        span = float(ranges[big]) if ranges[big] > 0 else 1.0
        err = fmu - lin
        fits[name] = OutputFit(
            nrmse=float(np.sqrt(np.mean(err**2)) / span),
            final_fmu=float(fmu[big, -1]),
            final_model=float(lin[big, -1]),
            final_error=float(abs(err[big, -1]) / span),
        )
    return fits


def _diagnose(fit: ModelFit, plant: Any, plan: StepPlan, model: np.ndarray, start: Mapping[str, float]) -> ModelFit:
    """A poor fit's likely cause: the same steps at a quarter of the amplitude (see the module docstring)."""
    quarter = run_steps(plant, plan, initial=_reset_values(plant, start), factor=0.25)
    fits = _fits(quarter, 0.25 * model, list(fit.outputs))
    small = max((max(f.nrmse, f.final_error) for f in fits.values()), default=0.0)
    if small < SHRINK * fit.worst:
        cause = f"the plant's nonlinearity at that amplitude (at a quarter of it the worst error falls to {small:.2g})"
    elif fit.interface == "cs":
        cause = (
            f"the FMU's own Co-Simulation solver or step at Ts = {fit.Ts:g} s (the error stays at {small:.2g} with a "
            'quarter of the amplitude); run it through Model Exchange (interface = "me")'
        )
    else:
        cause = (
            f"the FMU's own solver or step (the error stays at {small:.2g} with a quarter of the amplitude): "
            "check its solver settings, or a model that is not smooth at the point"
        )
    return replace(fit, cause=cause, worst_quarter=small)
