"""The scenario's plant, built from its ``[plant]`` table and checked against the artifact and the scenario's signal
names (the run, its twin and SIL each build one)."""

from __future__ import annotations

import functools
import os
from pathlib import Path

from gainlink.errors import GainlinkError, ScenarioError, did_you_mean
from gainlink.shipping.artifact import Artifact

from ..plants.base import Plant, check_dimensions
from ..plants.config import plant_from_config
from .scenario import Scenario


def build_plant(scenario: Scenario, *, artifact: Artifact) -> Plant:
    """The scenario's plant, checked against the artifact and the scenario's signal names."""
    base = scenario.path.parent if scenario.path is not None else _folder(os.getcwd())
    plant = plant_from_config(scenario.plant, artifact=artifact, base_dir=base)
    try:
        check_dimensions(plant, m=artifact.m, p=artifact.p, artifact=str(scenario.artifact_path))
        for name in scenario.reference:
            if name not in artifact.signals["references"]:
                raise ScenarioError(
                    f"scenario: reference {name!r} is not a reference of the artifact"
                    f"{did_you_mean(name, artifact.signals['references'])} "
                    f"(references: {', '.join(artifact.signals['references']) or 'none'})"
                )
        for name in scenario.noise:
            if name not in plant.output_names:
                raise ScenarioError(
                    f"scenario: noise on {name!r}, which is not a plant output{did_you_mean(name, plant.output_names)}"
                    f" ({', '.join(plant.output_names)})"
                )
        for d in scenario.disturbances:
            if d.input not in plant.input_names:
                raise ScenarioError(
                    f"scenario: disturbance on {d.input!r}, which is not a plant input"
                    f"{did_you_mean(d.input, plant.input_names)} ({', '.join(plant.input_names)})"
                )
    except GainlinkError:
        plant.close()
        raise
    return plant


@functools.lru_cache(maxsize=1)
def _folder(cwd: str) -> Path:
    """The working directory ``cwd`` as a Path, made once while it stays the same (``Path.cwd()`` built a new one
    for every plant of a campaign block: ~6 us each, more than the pendulum's own construction)."""
    return Path(cwd)
