"""The scheduled law inside a SIL run (:mod:`.sil_scheduled`): the controller behind one step interface (the float64
reference or the scheduled C through ctypes), the closed-loop twin and the model twin.

The model twin of a scheduled artifact closes the float64 scheduled law around the design's own model *at the
sigma it runs at*: per step the points' sampled plants ``Ad Bd Cd Dd`` and trims ``u_op y_op x_op`` interpolated
linearly at the sigma the twin's own law used last (before its first step, the run's start sigma), advanced in
absolute coordinates as the local affine model there (:class:`~gainlink.hil.plants.scheduled_model.ScheduledModel`).
With sigma an external signal this is the run's sigma; with sigma a measured output it is the model's own output
(the model twin is a closed prediction, not driven by the plant). It needs ``x_op`` at every point (the spec's
operating points; zeros when no point has a trim); without it the model twin is off and the report says why.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from gainlink.proof.scheduled_reference import ScheduledLoop
from gainlink.proof.twin import TwinTrace
from gainlink.shipping.artifact import Artifact
from gainlink.shipping.scheduled import interval, lerp

from ..plants.base import Plant
from ..plants.fmi import signal_name
from ..plants.scheduled_model import ScheduledModel, operating_states

GL_SATURATED, GL_ERR_NANINF = 1, -2


@dataclass(frozen=True)
class SchedOut:
    """One step of a scheduled controller: command, status, saturation bits, sigma used and its flags."""

    u: np.ndarray
    status: int
    sat_mask: int
    sigma: float
    sigma_flags: int


class ReferenceScheduled:
    """The float64 scheduled law (:class:`~gainlink.proof.scheduled_reference.ScheduledLoop`)."""

    def __init__(self, artifact: Artifact) -> None:
        self.law = ScheduledLoop(artifact)
        self.kind = {"kind": "reference (float64 scheduled law)"}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> SchedOut:
        """One sample: absolute ``y``, ``r`` and external scheduling signals ``s``."""
        res = self.law.step(y, r, s)
        status = GL_ERR_NANINF if res.fault else (GL_SATURATED if res.saturated.any() else 0)
        mask = int(np.sum(res.saturated.astype(int) << np.arange(res.saturated.size)))
        return SchedOut(u=res.u, status=status, sat_mask=mask, sigma=res.sigma, sigma_flags=res.sigma_flags)


class NativeScheduled:
    """The scheduled C loop of the host library (``gl_sched_step`` through the law's one host binding, one sample a
    call)."""

    def __init__(self, artifact: Artifact, *, library=None) -> None:
        from gainlink.engines.sched_native import NativeScheduledLoop

        self.loop = NativeScheduledLoop(artifact, library=library)
        self.index = artifact.n + artifact.m + artifact.p + artifact.q  # sigma in the state vector
        self.kind = {"kind": "firmware (host scheduled C loop, ctypes)", "library": str(self.loop._lib._name)}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> SchedOut:
        """One sample: absolute ``y``, ``r`` and external scheduling signals ``s``."""
        raw = self.loop.run_raw(y[None, :], r[None, :], s[None, :] if s.size else None)
        return SchedOut(
            u=raw["u"][0].astype(float),
            status=int(raw["status"][0]),
            sat_mask=int(raw["sat"][0]),
            sigma=float(raw["state"][0, self.index]),
            sigma_flags=int(raw["sflags"][0]),
        )


class ScheduledTwin:
    """A float64 scheduled law closed around a plant-like pair (``outputs``, ``advance``), one sample at a time.

    The closed-loop twin (a second instance of the run's plant) and the model twin (:class:`ScheduledModel`) are
    both this; ``on_sigma`` hears the sigma of each step (the model follows it), ``on_signals`` the external
    scheduling signals before each step (a plant that follows them). ``trace`` has no integrator
    (the velocity form keeps none): its ``z`` is NaN.
    """

    def __init__(
        self,
        artifact: Artifact,
        *,
        outputs: Callable[[], np.ndarray],
        advance: Callable[[np.ndarray], None],
        steps: int,
        on_sigma: Callable[[float], None] | None = None,
        on_signals: Callable[[np.ndarray], None] | None = None,
    ) -> None:
        self.law = ScheduledLoop(artifact)
        self._outputs, self._advance, self._on_sigma, self._on_signals = outputs, advance, on_sigma, on_signals
        a = artifact
        self.Y, self.U, self.SIG = np.zeros((steps, a.p)), np.zeros((steps, a.m)), np.zeros(steps)
        self.q = a.q

    def step(self, k: int, *, noise: np.ndarray, r: np.ndarray, d: np.ndarray, s: np.ndarray) -> None:
        """Sample ``k``: sample the twin plant (plus ``noise``), run the law, apply ``u + d``."""
        if self._on_signals is not None:
            self._on_signals(s)
        y = np.asarray(self._outputs(), dtype=float) + noise
        res = self.law.step(y, r, s)
        self.Y[k], self.U[k], self.SIG[k] = y, res.u, res.sigma
        if self._on_sigma is not None:
            self._on_sigma(res.sigma)
        self._advance(res.u + d)

    def trace(self, steps: int) -> TwinTrace:
        """The twin's first ``steps`` samples (``z`` NaN)."""
        return TwinTrace(y=self.Y[:steps].copy(), u=self.U[:steps].copy(), z=np.full((steps, self.q), np.nan))


def start_scheduled_model_twin(
    artifact: Artifact, *, plant: Plant, steps: int, sigma0: float
) -> tuple[ScheduledTwin | None, str]:
    """The scheduled model twin started at the plant's state (by name; else ``x_op`` at ``sigma0``), and a note."""
    X_op = operating_states(artifact)
    if X_op is None:
        return None, "off: the schedule's points give no x_op (the model's absolute state is unknown)"
    S = artifact.schedule
    i, lam = interval(S.points, S.clip(sigma0))
    names = list(artifact.signals["states"])
    state = dict(zip((signal_name(s) for s in plant.state_names), np.asarray(plant.state(), float)))
    if all(s in state for s in names):
        x0, note = np.array([state[s] for s in names]), "the plant's initial state (the model at the run's sigma)"
    else:
        x0, note = lerp(X_op, i, lam), "x_op at the start sigma (the plant's states do not map onto the model's)"
    model = ScheduledModel(artifact, x_op=X_op, x0=x0, sigma=sigma0)
    twin = ScheduledTwin(artifact, outputs=model.outputs, advance=model.advance, steps=steps, on_sigma=model.follow)
    return twin, note
