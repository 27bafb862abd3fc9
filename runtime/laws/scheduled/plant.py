"""The design's own model of a scheduled artifact: the points' sampled plants and trims interpolated linearly at a
moving sigma (the model a scheduled law believes in, between and across its points).

Per sample, at the current sigma (``Ad Bd Cd Dd`` and ``u_op y_op x_op`` interpolated there), in absolute
coordinates::

    x+ = x_op + Ad (x - x_op) + Bd (u - u_op)          y = y_op + Cd (x - x_op) + Dd (u - u_op)

The model twin of a scheduled run closes the float64 law around this model, which follows the sigma the twin's own
law uses (:meth:`ScheduledModel.follow`); the scenario plant ``kind = "lpv_model"``
(:mod:`gainlink.hil.plants.lpv_model`) is the same model following an external scheduling signal or its own
scheduled output. ``x_op`` comes from the points (the spec's operating points); when no point has a trim at all,
the model is about the origin.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .block import interval, lerp


def operating_states(artifact: Any) -> np.ndarray | None:
    """``x_op`` of every point (N, n): as given, zeros when no point has any trim, None when unknown."""
    S, entries = artifact.schedule, artifact.data["schedule"]["point"]
    if all("x_op" in e for e in entries):
        return np.array([e["x_op"] for e in entries], dtype=float)
    if not (np.any(S.u_op) or np.any(S.y_op)):
        return np.zeros((S.points.size, artifact.n))
    return None


class ScheduledModel:
    """The interpolated model at a moving sigma (module docstring), absolute state ``x``."""

    def __init__(self, artifact: Any, *, x_op: np.ndarray, x0: np.ndarray, sigma: float) -> None:
        self.S, self.X_op, self.x = artifact.schedule, x_op, np.asarray(x0, dtype=float).copy()
        self.sigma, self.u_prev = float(sigma), None

    def _frozen(self):
        S = self.S
        i, lam = interval(S.points, S.clip(self.sigma))
        Ad, Bd, Cd, Dd = S.plant_at(self.sigma)
        u_op, y_op = S.trim_at(self.sigma)
        return Ad, Bd, Cd, Dd, u_op, y_op, lerp(self.X_op, i, lam)

    def outputs(self) -> np.ndarray:
        """``y_op + Cd (x - x_op) + Dd (u_prev - u_op)`` at the current sigma (``u_prev``: ``u_op`` at first)."""
        _, _, Cd, Dd, u_op, y_op, x_op = self._frozen()
        du = np.zeros_like(u_op) if self.u_prev is None else self.u_prev - u_op
        return y_op + Cd @ (self.x - x_op) + Dd @ du

    def advance(self, u: np.ndarray) -> None:
        """One sample under the held command ``u`` (absolute)."""
        Ad, Bd, _, _, u_op, _, x_op = self._frozen()
        self.x = x_op + Ad @ (self.x - x_op) + Bd @ (np.asarray(u, float) - u_op)
        self.u_prev = np.asarray(u, float).copy()

    def follow(self, sigma: float) -> None:
        """The sigma the next output and advance are taken at."""
        self.sigma = float(sigma)
