"""The discrete plant a controller is designed for: ZOH or Tustin sampling of a continuous spec."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..lti import StateSpaceModel
from ..spec import PlantSpec


@dataclass(frozen=True, kw_only=True)
class Discretised(StateSpaceModel):
    """The discrete plant the controller is designed for (``method``: zoh, tustin, or none for a discrete spec)."""

    method: str


def discretise(spec: PlantSpec) -> Discretised:
    """ZOH or Tustin discretisation of a continuous spec; a discrete spec is returned as is."""
    import control

    plant = spec.plant
    names = {"states": plant.states, "inputs": plant.inputs, "outputs": plant.outputs, "Ts": spec.Ts}
    if not plant.continuous:
        return Discretised(A=plant.A, B=plant.B, C=plant.C, D=plant.D, method="none", **names)
    sysd = control.c2d(control.ss(plant.A, plant.B, plant.C, plant.D), spec.Ts, method=spec.discretization)
    matrices = {k: np.asarray(getattr(sysd, k), float) for k in ("A", "B", "C", "D")}
    return Discretised(**matrices, method=spec.discretization, **names)


def augment(d: Discretised, Ci: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The plant augmented with ``z+ = z + Ts (r - Ci y)`` (taken at r = 0) for integral action."""
    n, _ = d.B.shape
    q = Ci.shape[0]
    Aa = np.block([[d.A, np.zeros((n, q))], [-Ts * Ci @ d.C, np.eye(q)]])
    Ba = np.vstack([d.B, -Ts * Ci @ d.D])
    return Aa, Ba
