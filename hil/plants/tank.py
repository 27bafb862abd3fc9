"""A tank drained through an orifice and filled by a pump with a first-order lag: the nonlinear plant of
``examples/tank_scheduled.toml``, whose level's time constant ``2 sqrt(h) / c`` grows 5x across its envelope::

    dq/dt = (u - q) / tau_p          dh/dt = (q - c sqrt(h+)) / (area + flare h+),   h+ = max(h, 0)

(``q`` pump flow, ``h`` level, ``u`` pump command; the section ``area`` 1 m^2 and ``flare`` 0 by default, a
cylinder; ``examples/tank_showcase.toml`` widens with its level). The project's FMU ``tank`` is the same model.
A drained tank stays at ``h >= 0``: the orifice passes nothing below empty, and a negative level is clamped to
zero after each sample.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from .base import PLANTS
from .models import OdePlant, _ode_factory


class Tank(OdePlant):
    """The orifice tank (module docstring); parameters ``c`` (m^2.5/s), ``tau_p`` (s), ``area`` (m^2) and
    ``flare`` (m^2 per m of level)."""

    name = "tank"
    vectorised = True
    native = ("c", "tau_p", "area", "flare")
    all_inputs = ("u",)
    state_names = ("q", "h")
    default_outputs = ("h",)
    defaults: ClassVar[Mapping[str, float]] = {"c": 0.4, "tau_p": 0.1, "area": 1.0, "flare": 0.0}

    def rates(self, X: np.ndarray, U: np.ndarray, P: Mapping[str, np.ndarray]) -> np.ndarray:
        h = np.maximum(X[:, 1], 0.0)
        section = P["area"] + P["flare"] * h
        out = np.empty_like(X)
        out[:, 0], out[:, 1] = (U[:, 0] - X[:, 0]) / P["tau_p"], (X[:, 0] - P["c"] * np.sqrt(h)) / section
        return out

    def clamp(self, X: np.ndarray) -> np.ndarray:
        """A drained tank stays empty: a negative level is clamped to zero after each sample."""
        X[:, 1] = np.maximum(X[:, 1], 0.0)
        return X


PLANTS.register("tank")(_ode_factory(Tank))
