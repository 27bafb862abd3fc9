"""What ``linearize`` records about the model it wrote: the interface runs will use at the spec's ``Ts`` (and
why), and how well the model fits the FMU through it (:mod:`.model_fit`). The record is the spec's
``[linearization]`` table; ``design`` copies its verdicts into the artifact's provenance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .fmi import fmu_sha256, signal_name
from .fmu_check import TOLERANCE
from .fmu_interface import InterfaceChoice, check_setup, choose_interface
from .model_fit import ModelFit, fit_model


@dataclass(frozen=True)
class Validity:
    """The interface choice and the fit of one linearisation, and the spec's ``[linearization]`` record."""

    choice: InterfaceChoice
    fit: ModelFit
    record: dict

    def warning(self) -> str | None:
        return self.fit.warning()


def check_linearization(lin: Any, *, path: Path, md: Any, Ts: float, interface: str = "auto") -> Validity:
    """Choose the interface runs at ``Ts`` will use (``interface`` forces one) and fit ``lin`` through it."""
    params, start = _point(md, lin)
    args = {"path": path, "inputs": list(lin.inputs), "outputs": list(lin.outputs), "parameters": params}
    setup = check_setup(md, plant_args=args, solver={}, start=start)
    choice = choose_interface(md, requested=interface, step=Ts, setup=setup)
    names = ([signal_name(n) for n in lin.inputs], [signal_name(n) for n in lin.outputs])
    fit = fit_model(lin, choice=choice, plant_args=setup.plant_args, start=setup.start, Ts=Ts, names=names)
    return Validity(choice=choice, fit=fit, record=_record(lin, path=path, choice=choice, fit=fit))


def _point(md: Any, lin: Any) -> tuple[dict, dict]:
    """The operating point as plant parameters (``--at`` values of parameters) and start values (the states
    there, for a continuous model, and the inputs)."""
    causality = {v.name: v.causality for v in md.modelVariables}
    params = {k: float(v) for k, v in lin.point.items() if causality.get(k) == "parameter"}
    start = {k: float(v) for k, v in lin.point.items() if k not in params}
    if lin.Ts is None:  # an identified model's states are not the FMU's
        start.update({s: float(v) for s, v in zip(lin.states, lin.x0)})
    start.update({u: float(v) for u, v in zip(lin.inputs, lin.u0)})
    return params, start


def _record(lin: Any, *, path: Path, choice: InterfaceChoice, fit: ModelFit) -> dict:
    rec: dict[str, Any] = {
        "fmu": lin.model_name,
        "fmu_sha256": fmu_sha256(path),
        "method": lin.method,
        "Ts": fit.Ts,
        "interface": choice.interface,
        "interface_reason": choice.reason,
    }
    check = choice.check
    if check is not None:
        rec["interface_check"] = {"tolerance": TOLERANCE, "steps": check.steps, "seconds": round(check.seconds, 3)}
        if math.isfinite(check.max_error):
            rec["interface_check"]["max_error"] = check.max_error
        if check.failure:
            rec["interface_check"]["failure"] = check.failure
    rec["fit_steps"] = fit.steps
    rec["fit_amplitude"] = fit.amplitudes
    rec["fit"] = fit.table()
    warning = fit.warning()
    if warning:
        rec["fit_warning"] = warning
    return rec
