"""A linear parameter-varying plant, ``kind = "lpv_model"``: the sampled plants and trims of an artifact's points
interpolated at a moving sigma (:class:`gainlink.laws.scheduled.plant.ScheduledModel`), whose dynamics follow an
external scheduling signal (the run hands it the signals each step through :meth:`LpvModelPlant.schedule`) or its
own output. It advances by the artifact's ``Ts`` only.

It is a plant, stepped by the loop as every other kind, so it is named for what it is (an LPV model), not after the
law whose artifact holds its points; the points come from a scheduled artifact, the only one that has them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gainlink.errors import PlantError, did_you_mean
from gainlink.laws.scheduled.plant import ScheduledModel, operating_states
from gainlink.shipping.law_c import sigma_name

from .base import PLANTS, Plant


class LpvModelPlant(Plant):
    """:class:`ScheduledModel` as a scenario plant; sigma from :meth:`schedule` (external) or its own output."""

    def __init__(self, artifact: Any) -> None:
        if artifact is None or sigma_name(artifact) is None:
            raise PlantError(
                "plant lpv_model: the scenario's artifact has no points to interpolate (a scheduled "
                "artifact, schema 2, has)"
            )
        X_op = operating_states(artifact)
        if X_op is None:
            raise PlantError("plant lpv_model: the schedule's points give no x_op")
        self.a, self.X_op = artifact, X_op
        self.name = f"{artifact.name} LPV model"
        sig = artifact.signals
        self.state_names, self.input_names, self.output_names = (
            tuple(sig["states"]), tuple(sig["inputs"]), tuple(sig["outputs"]))  # fmt: skip
        self.model = ScheduledModel(artifact, x_op=X_op, x0=X_op[0], sigma=float(artifact.schedule.points[0]))

    def reset(self, *, initial: Mapping[str, float]) -> None:
        S = self.a.schedule
        x = self.X_op[0].copy()
        for key, value in initial.items():
            if key not in self.state_names:
                raise PlantError(
                    f"plant {self.name} has no state {key!r}{did_you_mean(key, self.state_names)} "
                    f"(has: {', '.join(self.state_names)})"
                )
            x[self.state_names.index(key)] = float(value)
        self.model = ScheduledModel(self.a, x_op=self.X_op, x0=x, sigma=float(S.points[0]))
        if S.source == "output":
            self._own_sigma()

    def _own_sigma(self) -> None:
        S = self.a.schedule
        self.model.follow(S.clip(float(self.model.outputs()[S.index])))

    def schedule(self, s: np.ndarray) -> None:
        """The external scheduling signals of the coming sample (ignored when sigma is an output)."""
        S = self.a.schedule
        if S.source == "external":
            self.model.follow(S.clip(float(np.asarray(s, float)[S.index])))

    def outputs(self) -> np.ndarray:
        return self.model.outputs()

    def state(self) -> np.ndarray:
        return self.model.x.copy()

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        if abs(dt - self.a.Ts) > 1e-12 * self.a.Ts:
            raise PlantError(f"plant {self.name} advances by the artifact's Ts = {self.a.Ts:g} s only")
        self.model.advance(u)
        if not np.all(np.isfinite(self.model.x)):
            raise PlantError(f"plant {self.name}: state became non-finite")
        if self.a.schedule.source == "output":
            self._own_sigma()

    def save_state(self) -> Any:
        return (self.model.x.copy(), self.model.sigma, self.model.u_prev)

    def restore_state(self, snapshot: Any) -> None:
        x, sigma, u_prev = snapshot
        self.model.x, self.model.sigma, self.model.u_prev = x.copy(), sigma, u_prev


@PLANTS.register("lpv_model")
def _factory(config: Mapping[str, Any], *, artifact: Any = None, **_context: Any) -> Plant:
    unknown = sorted(set(config) - {"kind"})
    if unknown:
        raise PlantError(f"plant lpv_model: unknown key(s) {', '.join(unknown)} (it takes only kind)")
    return LpvModelPlant(artifact)
