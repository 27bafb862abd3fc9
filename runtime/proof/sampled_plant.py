"""The one discrete plant model every loop here closes around: the design's sampled plant about its operating point.

``x+ = Ad x + Bd (u - u_op + d)``, ``y = y_op + Cd x + Dd (u_prev - u_op)``: the state is a deviation from the
operating point, the command ``u`` and the output ``y`` are absolute, ``d`` is a disturbance at the plant's input.
The feed-through acts on the previous command: the controller computes ``u`` from ``y``, so ``y`` cannot depend on
the same sample's ``u`` without an algebraic loop. The closed-loop simulation, the float32 fidelity check and PIL's
artifact plant step this class; the bridge's linear plant steps the same model through fixed-order products of its
own (``gainlink.hil.plants.linear.rowsum``), so that a campaign block gives each run the same bits as the run alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..shipping.law_c import ONE_OPERATING_POINT, require_structure


class SampledPlant:
    """A discrete plant ``(Ad, Bd, Cd, Dd)`` about ``(u_op, y_op)`` (zeros by default), started at ``x0``."""

    def __init__(
        self,
        Ad: np.ndarray,
        Bd: np.ndarray,
        Cd: np.ndarray,
        Dd: np.ndarray,
        *,
        u_op: np.ndarray | None = None,
        y_op: np.ndarray | None = None,
        x0: np.ndarray | None = None,
    ) -> None:
        self.Ad, self.Bd, self.Cd, self.Dd = Ad, Bd, Cd, Dd
        n, m = Bd.shape
        self.u_op = np.zeros(m) if u_op is None else np.asarray(u_op, dtype=float)
        self.y_op = np.zeros(Cd.shape[0]) if y_op is None else np.asarray(y_op, dtype=float)
        self.x = np.zeros(n)
        self.du_prev = np.zeros(m)
        self.reset(x0)

    @classmethod
    def from_artifact(cls, artifact: Any, *, x0: np.ndarray | None = None) -> SampledPlant:
        """The artifact's own plant in the design's coordinates (those of a state a user gives), about its
        operating point (a scheduled artifact has one per point: ArtifactError)."""
        require_structure(artifact, ONE_OPERATING_POINT, "the artifact's own plant")
        return cls(*artifact.design_plant(), u_op=artifact.u_op, y_op=artifact.y_op, x0=x0)

    def reset(self, x0: np.ndarray | None = None) -> None:
        """Back to ``x0`` (a deviation; zeros by default) with no previous command."""
        n = self.Ad.shape[0]
        self.x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).reshape(n).copy()
        self.du_prev = np.zeros(self.Bd.shape[1])

    def outputs(self) -> np.ndarray:
        """The absolute output of this sample."""
        return self.y_op + self.Cd @ self.x + self.Dd @ self.du_prev

    def advance(self, u: np.ndarray, *, d: Any = None, transition: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Apply the absolute command ``u`` (plus the input disturbance ``d``) for one sample; ``transition``
        replaces ``(Ad, Bd)`` for this step (a continuous model sampled at a varying step)."""
        Ad, Bd = (self.Ad, self.Bd) if transition is None else transition
        self.du_prev = np.asarray(u, dtype=float) - self.u_op
        self.x = Ad @ self.x + Bd @ (self.du_prev if d is None else self.du_prev + d)

    @property
    def state(self) -> np.ndarray:
        """A copy of the state (deviation from the operating point)."""
        return self.x.copy()

    def save(self) -> tuple[np.ndarray, np.ndarray]:
        """A snapshot to :meth:`restore`."""
        return self.x.copy(), self.du_prev.copy()

    def restore(self, snapshot: tuple[np.ndarray, np.ndarray]) -> None:
        """Return to a :meth:`save` snapshot."""
        self.x, self.du_prev = snapshot[0].copy(), snapshot[1].copy()
