"""Does an FMU's Co-Simulation solver reproduce its Model Exchange derivatives at a step? Checked once, cached.

An FMU exported with both interfaces can disagree with itself: OpenModelica's Co-Simulation export without CVODE
steps with explicit Euler, which at 1 ms removes a mass-spring-damper's damping (FIELD-NOTES, 2026-11-25). The
Model Exchange derivatives are the model (they are what ``linearize`` reads); Co-Simulation is the cheap way to
run it (fmpy's CVode costs ~30x a Co-Simulation step), so it is kept wherever it reproduces them.

The check drives both interfaces from the same start with the same small input steps (:mod:`.step_response`,
planned on the Model Exchange Jacobians there) at the run's step, and compares the free response and each step
response: Co-Simulation passes when no output differs by more than :data:`TOLERANCE` of the Model Exchange
response's range. 0.1 %: an order of magnitude below what the fit warning (:mod:`.model_fit`) and the model twin
flag, so choosing Co-Simulation never changes a verdict, yet far above CVode's own error at its default
tolerance, so a sound Co-Simulation solver passes.

The result is cached in ``.cache/interface`` by the FMU's sha256, the step and everything else the experiment
depends on (start values, inputs at the start, variable mapping, solver settings).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import GainlinkError, PlantError
from gainlink.fileio import atomic_write_text

from ..paths import cache_dir
from .fmi import fmu_sha256
from .fmi_me import provides_directional
from .fmu import FmuPlant
from .fmu_me import FmuModelExchangePlant
from .jacobian import jacobians, signals
from .step_response import StepRuns, discretise, plan_steps, run_steps

log = logging.getLogger(__name__)

TOLERANCE = 1e-3
REFERENCE_RTOL = 1e-10  # CVode's own error at the plant's default 1e-8 reached ~1e-3 of a small step's response
CHECK_VERSION = 2


@dataclass(frozen=True)
class InterfaceCheck:
    """The outcome: ``passed`` when Co-Simulation reproduces Model Exchange within :data:`TOLERANCE`;
    ``max_error`` is the largest difference relative to the Model Exchange response's range, ``seconds`` what
    the check cost when it ran (``cached``: read from the cache instead)."""

    passed: bool
    max_error: float
    step: float
    steps: int
    amplitudes: dict
    seconds: float
    fmu_sha256: str
    failure: str | None = None  # Co-Simulation failed at this step (the FMU's reason)
    cached: bool = False

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class CheckSetup:
    """What both interfaces are built and started with: the plant arguments (path, inputs, outputs, states,
    parameters), the values set at the start (states, inputs) and the Model Exchange solver's settings."""

    plant_args: dict
    start: dict
    solver: dict


def check_cosimulation(md: Any, setup: CheckSetup, *, step: float, use_cache: bool = True) -> InterfaceCheck:
    """Whether Co-Simulation reproduces Model Exchange at ``step`` (cached; see the module docstring).
    ``use_cache = False`` checks afresh (and still records the verdict)."""
    path = Path(setup.plant_args["path"])
    sha = fmu_sha256(path)
    key = _cache_key(sha, setup, step)
    cached = _read_cache(key) if use_cache else None
    if cached is not None:
        return cached
    t0 = time.perf_counter()
    plan = _plan(path, md, setup, step)
    me_runs = _runs(FmuModelExchangePlant(**setup.plant_args, **_reference_solver(setup.solver)), plan, setup.start)
    failure = None
    try:
        error = _max_relative_difference(_runs(FmuPlant(**setup.plant_args), plan, setup.start), me_runs)
    except PlantError as exc:  # Co-Simulation cannot run this step at all: it reproduces nothing
        error, failure = float("inf"), str(exc)
    inputs = setup.plant_args.get("inputs") or [v.name for v in md.modelVariables if v.causality == "input"]
    result = InterfaceCheck(
        passed=bool(error <= TOLERANCE),
        max_error=float(error),
        step=float(step),
        steps=plan.steps,
        amplitudes={name: float(a) for name, a in zip(inputs, plan.amplitudes)},
        seconds=time.perf_counter() - t0,
        fmu_sha256=sha,
        failure=failure,
    )
    _write_cache(key, result)
    return result


def _plan(path: Path, md: Any, setup: CheckSetup, step: float):
    """The step experiment, planned on the Model Exchange Jacobians at the start (no move to an equilibrium)."""
    args = setup.plant_args
    sig = signals(md, inputs=args.get("inputs"), outputs=args.get("outputs"), at=None)
    values = {**(args.get("parameters") or {}), **setup.start}
    sig = dataclasses.replace(sig, point=values)
    j = jacobians(path, md, sig, use_dd=provides_directional(path, md), to_equilibrium=False)
    Ad, Bd = discretise(j.A, j.B, step)
    return plan_steps(Ad, Bd, j.C, j.D, u0=j.u0, y0=j.y0, Ts=step)


def _reference_solver(solver: Mapping[str, float]) -> dict:
    """Model Exchange as the reference: CVode at least as tight as :data:`REFERENCE_RTOL`."""
    return {**solver, "rtol": min(float(solver.get("rtol", REFERENCE_RTOL)), REFERENCE_RTOL)}


def _runs(plant: Any, plan, start: Mapping[str, float]) -> StepRuns:
    try:
        return run_steps(plant, plan, initial=_states_only(plant, start))
    finally:
        plant.close()


def _states_only(plant: Any, start: Mapping[str, float]) -> dict:
    """The start values a reset sets (inputs are driven by the runs themselves)."""
    return {k: v for k, v in start.items() if k not in plant.input_names}


def _max_relative_difference(cs: StepRuns, me: StepRuns) -> float:
    """The largest |Co-Simulation - Model Exchange| over the free and the step responses, relative per output to
    the largest range Model Exchange moved it through in any of them."""
    runs_cs, runs_me = np.stack([cs.free, *cs.steps]), np.stack([me.free, *me.steps])  # (1 + m, K, p)
    scale = np.ptp(runs_me, axis=1).max(axis=0)  # (p,)
    diff = np.abs(runs_cs - runs_me).max(axis=(0, 1))
    rel = np.where(diff == 0, 0.0, diff / np.where(scale > 0, scale, np.inf))
    worst = float(rel.max()) if rel.size else 0.0
    return worst if np.isfinite(worst) and not (diff > 0)[scale == 0].any() else float("inf")


def _cache_key(sha: str, setup: CheckSetup, step: float) -> str:
    args = {k: v for k, v in setup.plant_args.items() if k != "path"}
    text = json.dumps(
        {"fmu": sha, "step": repr(float(step)), "args": args, "start": setup.start, "solver": setup.solver},
        sort_keys=True,
        default=repr,
    )
    return hashlib.sha256(f"check {CHECK_VERSION}\n{text}".encode()).hexdigest()


def _cache_path(key: str) -> Path:
    return cache_dir("interface") / f"{key[:32]}.json"


def _read_cache(key: str) -> InterfaceCheck | None:
    path = _cache_path(key)
    try:
        data = json.loads(path.read_text("utf-8"))
        return InterfaceCheck(**{**data, "cached": True})
    except FileNotFoundError:
        return None
    except (OSError, ValueError, TypeError):  # a broken entry is checked again and rewritten
        log.debug("interface cache %s unreadable", path, exc_info=True)
        return None


def _write_cache(key: str, result: InterfaceCheck) -> None:
    try:
        atomic_write_text(_cache_path(key), json.dumps(result.to_dict(), sort_keys=True) + "\n")
    except (OSError, GainlinkError):  # a read-only cache costs a re-check next time, nothing else
        log.debug("interface cache not written", exc_info=True)
