"""The plant plugin interface and its registry.

A plant is simulated by the bridge: it takes the controller's command (plus disturbances),
advances by a given time, and offers its outputs to be sampled. Implementations: FMUs through
fmpy (:mod:`gainlink.hil.plants.fmu`) and the built-in models (:mod:`gainlink.hil.plants.models`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from ..registry import Registry

PLANTS: Registry[Plant] = Registry(what="plant", error=PlantError)


class Plant(ABC):
    """A simulated plant with named inputs, outputs and states.

    Attributes
    ----------
    name : str
        Display name.
    input_names, output_names, state_names : tuple of str
        The signals in the order :meth:`advance` takes and :meth:`outputs` returns them.
    """

    name: str
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    state_names: tuple[str, ...]

    @abstractmethod
    def reset(self, *, initial: Mapping[str, float]) -> None:
        """Restart at time zero with the named states (or parameters) set from ``initial``."""

    @abstractmethod
    def outputs(self) -> np.ndarray:
        """The current outputs, in ``output_names`` order."""

    @abstractmethod
    def advance(self, *, u: np.ndarray, dt: float) -> None:
        """Hold input ``u`` (``input_names`` order) for ``dt`` seconds."""

    @abstractmethod
    def state(self) -> np.ndarray:
        """The current state vector, in ``state_names`` order."""

    @abstractmethod
    def save_state(self) -> Any:
        """Return an opaque snapshot of the full plant state."""

    @abstractmethod
    def restore_state(self, snapshot: Any) -> None:
        """Return to a snapshot taken by :meth:`save_state`."""

    def close(self) -> None:  # noqa: B027 - an optional hook: plants that hold nothing need not override it
        """Release resources (FMU instances, libraries); the default holds none and does nothing."""


def select(names: tuple[str, ...], wanted: Any, *, what: str, plant: str) -> list[int]:
    """Indices of ``wanted`` (a list of names, or ``None`` for all) in ``names``."""
    if wanted is None:
        return list(range(len(names)))
    if not isinstance(wanted, (list, tuple)) or not all(isinstance(w, str) for w in wanted):
        raise PlantError(f"plant {plant}: {what} must be a list of names")
    missing = [w for w in wanted if w not in names]
    if missing:
        raise PlantError(f"plant {plant} has no {what[:-1]} named {', '.join(missing)} (has: {', '.join(names)})")
    return [names.index(w) for w in wanted]


def check_dimensions(plant: Plant, *, m: int, p: int, artifact: str) -> None:
    """Fail with one line unless the plant has ``m`` inputs and ``p`` outputs."""
    if len(plant.input_names) != m or len(plant.output_names) != p:
        raise PlantError(
            f"plant {plant.name} has {len(plant.input_names)} input(s) ({', '.join(plant.input_names)}) and "
            f"{len(plant.output_names)} output(s) ({', '.join(plant.output_names)}), but artifact {artifact} "
            f"expects m={m} input(s) and p={p} output(s)"
        )
