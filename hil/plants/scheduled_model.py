"""The design's own model of a scheduled artifact as a plant: the points' sampled plants and trims interpolated
linearly at a moving sigma (the model a scheduled law believes in, between and across its points).

Per sample, at the current sigma (``Ad Bd Cd Dd`` and ``u_op y_op x_op`` interpolated there), in absolute
coordinates::

    x+ = x_op + Ad (x - x_op) + Bd (u - u_op)          y = y_op + Cd (x - x_op) + Dd (u - u_op)

The model twin of a scheduled run is this model (:mod:`gainlink.hil.loop.sched_law`), and so is the scenario plant
``kind = "scheduled_model"``: a plant whose dynamics follow an external scheduling signal (the run hands it the
signals each step through :meth:`ScheduledModel.schedule`) or its own scheduled output. It advances by the
artifact's ``Ts`` only. ``x_op`` comes from the points (the spec's operating points); when no point has a trim at
all, the model is about the origin.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gainlink.errors import PlantError, did_you_mean
from gainlink.shipping.scheduled import interval, lerp

from .base import PLANTS, Plant


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


class ScheduledModelPlant(Plant):
    """:class:`ScheduledModel` as a scenario plant; sigma from :meth:`schedule` (external) or its own output."""

    def __init__(self, artifact: Any) -> None:
        if artifact is None or artifact.schedule is None:
            raise PlantError("plant scheduled_model: the scenario's artifact must be scheduled (schema 2)")
        X_op = operating_states(artifact)
        if X_op is None:
            raise PlantError("plant scheduled_model: the schedule's points give no x_op")
        self.a, self.X_op = artifact, X_op
        self.name = f"{artifact.name} scheduled model"
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


@PLANTS.register("scheduled_model")
def _factory(config: Mapping[str, Any], *, artifact: Any = None, **_context: Any) -> Plant:
    unknown = sorted(set(config) - {"kind"})
    if unknown:
        raise PlantError(f"plant scheduled_model: unknown key(s) {', '.join(unknown)} (it takes only kind)")
    return ScheduledModelPlant(artifact)
