"""A run's two twins, computed after the run from its plan (:func:`gainlink.proof.twin.run_twin`): neither depends
on the run, so neither is on its per-sample path.

- The closed-loop twin: the law's float64 reference around a second instance of the scenario's plant, reset to the
  same initial state, with the run's noise, references, disturbances and external scheduling signals, every sample
  arriving and no faults (:mod:`gainlink.proof.twin`): what the implementation costs the closed loop.
- The model twin: the same law around the design's own model (:meth:`gainlink.laws.Law.design_model`: the lq law's
  discrete model about its operating point; a scheduled law's points interpolated at the sigma the twin's own law
  uses), started where the plant started (:class:`TwinStart`, taken when the plant was reset): how far the plant
  departs from the model the controller believes in (:mod:`.model_twin`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gainlink.errors import PlantError
from gainlink.proof.twin import TwinTrace, run_twin

from ..plants.base import Plant
from ..plants.fmi import signal_name
from ..plants.linear import LinearPlant


@dataclass(frozen=True)
class TwinStart:
    """Where a run's plant started, taken right after its reset: its state by name, whether that state is a
    deviation from the operating point (a linear plant's), and the sigma the run starts at (NaN: no sigma)."""

    state: dict[str, float]
    deviation: bool
    sigma: float


def twin_start(plant: Plant, *, sigma: float) -> TwinStart:
    """The :class:`TwinStart` of ``plant`` now (just reset)."""
    state = dict(zip((signal_name(s) for s in plant.state_names), np.asarray(plant.state(), dtype=float)))
    return TwinStart(state=state, deviation=isinstance(plant, LinearPlant), sigma=float(sigma))


@dataclass(frozen=True)
class Twins:
    """A run's twins (None: off) and what the report says about them: where the model twin started, and why a
    twin is off when it was asked for."""

    twin: TwinTrace | None
    model: TwinTrace | None
    model_note: str
    notes: dict[str, str]


def _follower(plant: Any) -> Any:
    """The plant's ``schedule(s)`` (a plant whose dynamics follow the external scheduling signals), else None."""
    return getattr(plant, "schedule", None)


def closed_loop_twin(law: Any, artifact: Any, *, plant: Plant, plan: Any, steps: int) -> TwinTrace:
    """The law's float64 reference around ``plant`` (a second instance, reset to the run's initial state) for the
    run's first ``steps`` samples."""
    Ts = artifact.Ts
    return run_twin(law.reference(artifact), outputs=plant.outputs, advance=lambda u: plant.advance(u=u, dt=Ts),
                    noise=plan.noise, R=plan.R, D=plan.D, S=plan.S, steps=steps,
                    on_signals=_follower(plant))  # fmt: skip


def model_twin(law: Any, artifact: Any, *, start: TwinStart, plan: Any, steps: int) -> tuple[TwinTrace | None, str]:
    """The law's float64 reference around the design's own model, started at ``start``; ``(None, why)`` when the
    artifact gives no such model."""
    model, note = law.design_model(artifact, state=start.state, deviation=start.deviation, sigma=start.sigma)
    if model is None:
        return None, note
    trace = run_twin(law.reference(artifact), outputs=model.outputs, advance=model.advance, noise=plan.noise,
                     R=plan.R, D=plan.D, S=plan.S, steps=steps, on_sigma=getattr(model, "follow", None))  # fmt: skip
    return trace, note


def run_twins(law: Any, artifact: Any, *, scenario: Any, plan: Any, start: TwinStart, steps: int, build) -> Twins:
    """The twins ``scenario`` asks for (``twin``, ``model_twin``) over the run's first ``steps`` samples;
    ``build()`` makes the second plant. A twin whose plant fails is off, and ``notes`` says why."""
    twin, model, note, notes = None, None, "", {}
    if scenario.twin:
        plant = build()
        try:
            plant.reset(initial=scenario.initial_state)
            twin = closed_loop_twin(law, artifact, plant=plant, plan=plan, steps=steps)
        except PlantError as exc:
            notes["twin_off"] = f"the twin's plant failed: {exc}"
        finally:
            plant.close()
    if scenario.model_twin:
        try:
            model, note = model_twin(law, artifact, start=start, plan=plan, steps=steps)
        except PlantError as exc:
            note = f"off: the model failed: {exc}"
        if model is None:
            notes["model_twin_off"] = note
    return Twins(twin=twin, model=model, model_note=note, notes=notes)
