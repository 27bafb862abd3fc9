"""float32 fidelity of a scheduled law at design time: the C's float32 arithmetic and the float64 law, each closing
its own loop around the design model, at each sigma of a sweep.

At each sigma of :func:`sweep` (the points and the middle of each interval between them) the plant is the design
model frozen there (the points' sampled plants and trims interpolated at sigma,
:meth:`~gainlink.laws.scheduled.block.Schedule.plant_at`), and the two laws are the C's arithmetic
(:class:`~gainlink.laws.scheduled.model.ScheduledFloat32Loop`, bit for bit the host and Cortex-M builds) and the
float64 law (:class:`~gainlink.laws.scheduled.reference.ScheduledLoop`). They run the observer-based law's
scenario (:mod:`gainlink.laws.lq.fidelity`: measurement noise, a reference step sized to half the room to the nearer
limit, a saturating input disturbance), sized with the frozen unsaturated law there. An external sigma is held at
the sweep's value; a sigma the law reads from an output moves with that output, as it does in the C (the plant
stays the model frozen at the sweep's value, so the run compares two arithmetics of one law in one scenario; it
does not simulate the envelope).

The verdict is the worst command deviation ``max |u32 - u64|`` over the sweep, relative to each input's limit span,
against the same threshold (:data:`~gainlink.laws.lq.fidelity.THRESHOLD`): simulated, not certified. ``design``
records it in ``checks.float32`` (:meth:`gainlink.laws.scheduled.law.ScheduledLaw.design`) unless the spec switches the
float32 check off.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...shipping.artifact import Artifact
from ...shipping.systems import controller_matrices
from ..lq.fidelity import Float32Fidelity, LoopPoint, fidelity_at, noise_sd
from .block import interval
from .model import ScheduledFloat32Loop
from .reference import ScheduledLoop


def sweep(points: np.ndarray) -> np.ndarray:
    """The sigmas a scheduled law's fidelity is measured at: its points and the middle of each interval."""
    pts = np.asarray(points, dtype=float)
    return np.sort(np.concatenate([pts, (pts[:-1] + pts[1:]) / 2]))


@dataclass(frozen=True)
class ScheduledFidelity:
    """What float32 costs a scheduled law in closed loop at each sigma of the sweep (module docstring)."""

    sweep: tuple[tuple[float, Float32Fidelity], ...]

    @property
    def worst(self) -> tuple[float, Float32Fidelity]:
        """The sigma with the largest command deviation, and its run."""
        return max(self.sweep, key=lambda item: item[1].max_rel_u)

    @property
    def max_rel_u(self) -> float:
        """The largest command deviation over the sweep, relative to the limit span."""
        return self.worst[1].max_rel_u

    @property
    def threshold(self) -> float:
        """The deviation above which ``design`` warns (:data:`~gainlink.laws.lq.fidelity.THRESHOLD`)."""
        return self.worst[1].threshold

    @property
    def ok(self) -> bool:
        """True when every sigma's command deviation is within the threshold."""
        return all(f.ok for _, f in self.sweep)

    def warning(self, name: str = "sigma") -> str | None:
        """A warning naming where (``name``: sigma's) and the remedies when float32 costs more than the threshold,
        else None (the realisation is not a remedy: a scheduled law keeps every point's estimate in the design's
        coordinates)."""
        if self.ok:
            return None
        sigma, f = self.worst
        return (
            f"float32 changes the scheduled closed loop: at {name} = {sigma:g} the C's command deviates from the "
            f"float64 law's by up to {f.max_rel_u:.3g} of the limit span on {f.worst_input} (threshold "
            f"{f.threshold:g}) in a {f.steps}-step run with noise, a reference step and a saturating disturbance; try "
            "a slower sample rate, a slower observer, or rescaled plant units"
        )

    def describe(self, name: str = "sigma") -> str:
        """One line: the worst deviation over the sweep, where (``name``: sigma's), and against the threshold."""
        sigma, f = self.worst
        return (
            f"float32 in closed loop at {len(self.sweep)} values of {name} (the points and between them, the model "
            f"frozen there; {f.steps} steps each, noise, reference step, saturating disturbance; simulated: not "
            f"certified): max |u32 - u64| {f.max_rel_u:.3g} of the limit span at {name} = {sigma:g}, max |y32 - y64| "
            f"{max(g.max_rel_y for _, g in self.sweep):.3g} of the output excursion "
            f"({'within' if self.ok else 'ABOVE'} {f.threshold:g})"
        )

    def to_dict(self) -> dict:
        """``checks.float32`` of a scheduled artifact: the worst sigma's run (the keys of the observer-based law's)
        with ``sigma``, and the deviations at every sigma of the sweep."""
        sigma, f = self.worst
        return f.to_dict() | {
            "sigma": sigma,
            "sweep": [{"sigma": s, "max_rel_u": g.max_rel_u, "max_rel_y": g.max_rel_y} for s, g in self.sweep],
        }


class _HeldSignals:
    """A scheduled law with its external signals held (``step(y, r)``, as the fidelity run steps a law)."""

    def __init__(self, loop, s: np.ndarray) -> None:
        self.loop, self.s = loop, s

    def step(self, y, r):
        return self.loop.step(y, r, self.s)


def frozen_point(
    artifact: Artifact, sigma: float, *, implementation: Callable[[Artifact], Any] = ScheduledFloat32Loop
) -> LoopPoint:
    """The scheduled law of ``artifact`` about the design model frozen at ``sigma`` (module docstring);
    ``implementation`` makes the law under test (``step(y, r, s)``), by default the C's arithmetic in numpy."""
    a, S = artifact, artifact.schedule
    u_op, y_op = S.trim_at(sigma)
    i, _ = interval(S.points, sigma)
    V = a.data["schedule"]["point"][i]["design"].get("observer", {}).get("V")  # the noise of the point below
    s = np.full(len(S.external), sigma)
    return LoopPoint(
        *S.plant_at(sigma), u_op=u_op, y_op=y_op, r_op=a.Ci @ y_op, u_min=a.u_min, u_max=a.u_max,
        controller=controller_matrices(a, sigma), noise_sd=None if V is None else noise_sd(V), radius=None,
        inputs=tuple(a.signals["inputs"]), model=lambda: _HeldSignals(implementation(a), s),
        reference=lambda: _HeldSignals(ScheduledLoop(a), s), shared=(a, S),
    )  # fmt: skip


def scheduled_fidelity(
    artifact: Artifact, *, seed: int = 0, implementation: Callable[[Artifact], Any] = ScheduledFloat32Loop
) -> ScheduledFidelity:
    """The float32 fidelity of a scheduled ``artifact`` at each sigma of :func:`sweep` (module docstring).

    Parameters
    ----------
    artifact : Artifact
        A scheduled design (its points' models are the plants of the runs).
    seed : int
        Seed of the measurement noise.
    implementation : callable
        Builds the law under test from the artifact (``step(y, r, s)`` returning ``u`` and ``saturated``); the
        default is the C's arithmetic in numpy.
    """
    runs = []
    for sigma in sweep(artifact.schedule.points):
        point = frozen_point(artifact, float(sigma), implementation=implementation)
        runs.append((float(sigma), fidelity_at(point, seed=seed)))
    return ScheduledFidelity(tuple(runs))
