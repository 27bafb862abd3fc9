"""The discrete plant a controller is designed for: ZOH or Tustin sampling of a continuous spec."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spec import PlantSpec


@dataclass(frozen=True)
class Discretised:
    """The discrete plant the controller is designed for (``method``: zoh, tustin, or none for a discrete spec)."""

    Ad: np.ndarray
    Bd: np.ndarray
    Cd: np.ndarray
    Dd: np.ndarray
    method: str


def discretise(spec: PlantSpec) -> Discretised:
    """ZOH or Tustin discretisation of a continuous spec; a discrete spec is returned as is."""
    import control

    plant = spec.plant
    if not plant.continuous:
        return Discretised(plant.A, plant.B, plant.C, plant.D, "none")
    sysd = control.c2d(control.ss(plant.A, plant.B, plant.C, plant.D), spec.Ts, method=spec.discretization)
    return Discretised(
        np.asarray(sysd.A, float),
        np.asarray(sysd.B, float),
        np.asarray(sysd.C, float),
        np.asarray(sysd.D, float),
        spec.discretization,
    )


def augment(d: Discretised, Ci: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The plant augmented with ``z+ = z + Ts (r - Ci y)`` (taken at r = 0) for integral action."""
    n, _ = d.Bd.shape
    q = Ci.shape[0]
    Aa = np.block([[d.Ad, np.zeros((n, q))], [-Ts * Ci @ d.Cd, np.eye(q)]])
    Ba = np.vstack([d.Bd, -Ts * Ci @ d.Dd])
    return Aa, Ba
