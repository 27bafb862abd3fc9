"""The ``fmu`` plant kind: which interface of an FMU a run simulates, and the plant built on it.

``interface = "cs"`` or ``"me"`` forces one. ``"auto"`` (the default) takes the Model Exchange derivatives as
the model: an FMU with one interface runs through it; with both, Co-Simulation runs only where it reproduces
Model Exchange at the run's step (:mod:`.fmu_check`, checked once and cached), else Model Exchange. Without a
run step (a plant built outside a run) there is nothing to check at, and Model Exchange runs.

The check starts where the run's model says the plant is: the artifact's operating point (its ``x_op`` on the
FMU's settable states, its ``u_op`` on the inputs), which is also where ``linearize`` checked, so a run finds
``linearize``'s cached result. The plant carries the choice as ``interface``, ``interface_reason`` and
``interface_check`` (the check's record, or None), which run reports and artifacts repeat.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from ..registry import take_keys
from .base import PLANTS, Plant
from .fmi import map_variables, read_description, resolve_fmu, settable_at_start, signal_name
from .fmu import FmuPlant, opened
from .fmu_check import TOLERANCE, CheckSetup, InterfaceCheck, check_cosimulation
from .fmu_me import FmuModelExchangePlant

PLANT_KEYS = {"kind", "fmu", "path", "inputs", "outputs", "parameters", "states", "interface", "rtol", "max_step"}
INTERFACES = ("auto", "cs", "me")


@dataclass(frozen=True)
class InterfaceChoice:
    """``interface`` ("cs" or "me") and why; ``check`` is the Co-Simulation check when one decided it."""

    interface: str
    reason: str
    check: InterfaceCheck | None = None


def choose_interface(md: Any, *, requested: str, step: float | None, setup: CheckSetup) -> InterfaceChoice:
    """The interface a run at ``step`` uses (see the module docstring); ``setup`` starts the check."""
    if requested not in INTERFACES:
        raise PlantError(f"plant fmu: interface must be auto, cs or me, not {requested!r}")
    has_cs, has_me = md.coSimulation is not None, md.modelExchange is not None
    if requested != "auto":
        return InterfaceChoice(requested, f'forced by interface = "{requested}"')
    if not (has_cs and has_me):
        only = "cs" if has_cs else "me"
        return InterfaceChoice(only, f"the FMU has {'Co-Simulation' if has_cs else 'Model Exchange'} only")
    if step is None:
        return InterfaceChoice("me", "no run step to check Co-Simulation at: Model Exchange, the model itself")
    check = check_cosimulation(md, setup, step=step)
    return InterfaceChoice("cs" if check.passed else "me", _reason(check), check)


def _reason(check: InterfaceCheck) -> str:
    at = f"at Ts = {check.step:g} s"
    if check.failure:
        return f"Co-Simulation fails {at} ({check.failure}): Model Exchange runs"
    how = f"max difference {check.max_error:.2g} of the response"
    if check.passed:
        return f"Co-Simulation reproduces the Model Exchange derivatives {at} ({how}, tolerance {TOLERANCE:g})"
    return (
        f"Co-Simulation does not reproduce the Model Exchange derivatives {at} ({how} > {TOLERANCE:g}): "
        "Model Exchange runs"
    )


def check_setup(
    md: Any, *, plant_args: Mapping[str, Any], solver: Mapping[str, float], start: Mapping[str, float]
) -> CheckSetup:
    """The check's inputs in one normal form (mapped names, settable start values only), so that ``linearize``
    and a run of the same FMU at the same point build the same cache key."""
    mapping = map_variables(md, inputs=plant_args.get("inputs"), outputs=plant_args.get("outputs"))
    args = {
        "path": Path(plant_args["path"]),
        "inputs": list(mapping.inputs),
        "outputs": list(mapping.outputs),
        "parameters": dict(sorted((plant_args.get("parameters") or {}).items())),
    }
    kept = {k: float(v) for k, v in sorted(start.items()) if settable_at_start(md, k) and k not in args["parameters"]}
    return CheckSetup(plant_args=args, start=kept, solver=dict(solver))


def start_from_artifact(md: Any, artifact: Any, *, inputs: Any, outputs: Any) -> dict:
    """The artifact's operating point in the FMU's names: ``x_op`` on states whose spec name matches, ``u_op`` on
    the mapped inputs (zeros without an operating point; empty without an artifact). A scheduled artifact has no
    single operating point: its first point's ``u_op`` stands for it."""
    if artifact is None:
        return {}
    mapping = map_variables(md, inputs=inputs, outputs=outputs)
    start = {}
    from gainlink.laws import law_of

    u_op = law_of(artifact).u_op(artifact)
    if len(mapping.inputs) == artifact.m:
        start.update({name: float(v) for name, v in zip(mapping.inputs, u_op)})
    if artifact.x_op is not None:
        x_op = dict(zip(artifact.signals["states"], np.asarray(artifact.x_op, float)))
        states = [d.variable.derivative.name for d in md.derivatives] if md.derivatives else []
        start.update({s: float(x_op[signal_name(s)]) for s in states if signal_name(s) in x_op})
    return start


@PLANTS.register("fmu")
def _fmu_factory(
    config: Mapping[str, Any], *, base_dir: Path | None = None, artifact: Any = None, **_context: Any
) -> Plant:
    cfg = take_keys(config, allowed=PLANT_KEYS, where="plant fmu", error=PlantError)
    path = resolve_fmu(fmu=cfg.get("fmu"), path=cfg.get("path"), base_dir=base_dir)
    requested = cfg.get("interface", "auto")
    md = read_description(path)
    args = dict(path=path, inputs=cfg.get("inputs"), outputs=cfg.get("outputs"), parameters=cfg.get("parameters"))
    solver = {k: float(cfg[k]) for k in ("rtol", "max_step") if k in cfg}
    if requested == "cs" and solver:
        raise PlantError('plant fmu: rtol and max_step set fmpy\'s solver, which runs only with interface = "me"')
    if requested == "cs" and md.coSimulation is None:
        raise PlantError(f'FMU {path} has no Co-Simulation interface (interface = "me" runs its Model Exchange)')
    start = start_from_artifact(md, artifact, inputs=args["inputs"], outputs=args["outputs"])
    setup = check_setup(md, plant_args=args, solver=solver, start=start) if requested == "auto" else None
    choice = choose_interface(md, requested=requested, step=None if artifact is None else artifact.Ts, setup=setup)
    plant: Any
    if choice.interface == "me":
        plant = opened(FmuModelExchangePlant, args | {"states": cfg.get("states")}, solver)
    else:
        plant = opened(FmuPlant, args | {"states": cfg.get("states")}, {})
    plant.interface_reason, plant.interface_check = choice.reason, choice.check
    return plant


def describe_interface(plant: Plant) -> dict:
    """What a report says about a plant's interface: ``{}`` for a plant that is not an FMU."""
    if not hasattr(plant, "interface_reason"):
        return {}
    check = getattr(plant, "interface_check", None)
    out = {"interface": plant.interface, "interface_reason": plant.interface_reason}
    if check is not None:
        out["interface_check"] = check.to_dict()
    return out
