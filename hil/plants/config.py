"""Build a plant from a scenario's ``[plant]`` table: a registered kind (built-in models, ``fmu``,
``linear``, ``python``) or a name an installed package registers in the entry-point group
``gainlink.plants`` (python-can's plugin style)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gainlink.errors import PlantError, did_you_mean

from . import fmu_interface, linear, lpv_model, models, python, tank  # noqa: F401 - each registers its kinds
from .base import PLANTS, Plant


def plant_from_config(config: Mapping[str, Any], *, artifact: Any = None, base_dir: Path | None = None) -> Plant:
    """Build a plant from its configuration table (``kind`` selects the plugin).

    Parameters
    ----------
    config : mapping
        The ``[plant]`` table.
    artifact : Artifact, optional
        The scenario's artifact (``kind = "linear"`` simulates its plant model by default).
    base_dir : Path, optional
        Folder that relative file names in the table are resolved against.
    """
    if not isinstance(config, Mapping) or not isinstance(config.get("kind"), str):
        raise PlantError(f"plant: the [plant] table needs a kind (one of: {', '.join(_known())})")
    kind = config["kind"]
    if kind not in PLANTS.names():
        plant = python.plugin_plant(kind, config)
        if plant is not None:
            return plant
        raise PlantError(f"unknown plant kind {kind!r}{did_you_mean(kind, _known())} (known: {', '.join(_known())})")
    return PLANTS.create(kind, config, artifact=artifact, base_dir=base_dir)


def _known() -> list[str]:
    return sorted(set(PLANTS.names()) | set(python.installed_plugins()))
