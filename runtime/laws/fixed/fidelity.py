"""Fixed-point fidelity at design time: the integer law in closed loop, its measured deviation beside the
certified bound.

The float32 check's scenario (:mod:`gainlink.laws.lq.fidelity`: measurement noise, a reference step, then a
saturating input disturbance), with the reference step (or initial offset) scaled down where needed so that the
undisturbed run keeps the samples and references within half their declared ranges' room around the operating
point (the certificate's premise; beyond the ranges samples are clipped, and that is measured as clipping), is
run three times around the design plant: the integer law
(:class:`~gainlink.laws.fixed.model.FixedPointLoop`), the float64 law with the same quantised coefficients and
sample clip (:class:`~gainlink.proof.derived_law.DerivedLoop` on ``FixedGains.ideal``: what the rounding bound is
about) and the design's float64 law (:class:`~gainlink.proof.reference.ReferenceLoop`). Reported, per input:

- ``max_abs_u_unsaturated``: the integer law against the quantised float64 law while neither loop has yet
  saturated an input or clipped a sample: the case the closed-loop certificate covers, beside its bound;
- ``max_rel_u``: the integer law against the design's law over the whole run (saturation included), relative
  to the limit span: what the fixed point costs the design, measured;
- whether the second-line saturation ever had to act (it must not, for samples within their ranges).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from ...proof.derived_law import DerivedLoop
from ...proof.reference import ReferenceLoop, StepResult
from ...shipping.artifact import Artifact
from ..lq.fidelity import (  # the float32 check's scenario, shared
    _scenario_and_reference_run,
    _simulate,
    artifact_point,
)
from .model import FixedPointLoop


@dataclass(frozen=True)
class FixedPointFidelity:
    """Measured deviations of the integer law in closed loop (module docstring)."""

    steps: int
    reference_scale: float
    unsaturated_steps: int
    max_abs_u_unsaturated: list[float]
    bound_closed_loop: list[float]
    max_rel_u: float
    max_rel_u_quantised: float
    saturated_fraction: float
    clipped_steps: int
    overflow: list[str]

    @property
    def within_bound(self) -> bool:
        """True when the unsaturated deviation is within the certified closed-loop bound on every input."""
        return bool(np.all(np.array(self.max_abs_u_unsaturated) <= np.array(self.bound_closed_loop)))

    def to_dict(self) -> dict:
        """JSON form for ``checks.fixed_point.measured``."""
        return asdict(self) | {"within_bound": self.within_bound}


class _Recorded(FixedPointLoop):
    """The integer law, remembering clips and second-line saturations."""

    def __init__(self, artifact: Artifact) -> None:
        super().__init__(artifact)
        self.clipped, self.overflow = [], set()

    def step(self, y, r=None) -> StepResult:
        res = self.step_samples(y, r)
        self.clipped.append(bool(res.clipped_y.any() or res.clipped_r.any()))
        self.overflow |= set(res.overflow)
        return StepResult(u=res.U * 2.0 ** -self.f["u"].astype(float), saturated=res.saturated, fault=res.fault)


def fixed_point_fidelity(artifact: Artifact, *, seed: int = 0) -> FixedPointFidelity:
    """Run the integer law, the quantised float64 law and the design's law in closed loop and compare.

    ``artifact`` must hold ``checks.fixed_point`` (a fixed-point design).
    """
    a = artifact
    point = artifact_point(a)  # the design plant about the operating point, as the float32 check runs it
    sc, ref = _scenario_and_reference_run(point, seed=seed)
    scale = _range_scale(a, sc, ref)
    if scale < 1.0:
        sc = replace(sc, r=sc.r * scale, x0=sc.x0 * scale)
        ref, _ = _simulate(point, ReferenceLoop(a), sc)
    integer = _Recorded(a)
    run, _ = _simulate(point, integer, sc)
    ideal, _ = _simulate(point, DerivedLoop(integer.g.ideal), sc)
    span = a.u_max - a.u_min
    events = run.saturated.any(axis=1) | ideal.saturated.any(axis=1) | np.array(integer.clipped)
    first = int(np.argmax(events)) if events.any() else sc.steps
    window = min(first, sc.pulse_at)
    dev = np.abs(run.u[:window] - ideal.u[:window])
    bound = a.checks["fixed_point"]["error"]["closed_loop"]
    return FixedPointFidelity(
        steps=sc.steps,
        reference_scale=scale,
        unsaturated_steps=window,
        max_abs_u_unsaturated=[float(x) for x in dev.max(axis=0, initial=0.0)],
        bound_closed_loop=[float(x) for x in bound],
        max_rel_u=float((np.abs(run.u - ref.u) / span).max(initial=0.0)),
        max_rel_u_quantised=float((np.abs(run.u - ideal.u) / span).max(initial=0.0)),
        saturated_fraction=float(ref.saturated.any(axis=1).mean()),
        clipped_steps=int(np.sum(integer.clipped)),
        overflow=sorted(integer.overflow),
    )


def _range_scale(a: Artifact, sc, ref) -> float:
    """The factor (at most 1) that keeps the run before the disturbance within half the declared ranges' room."""
    ranges = a.checks["fixed_point"]["ranges"]
    before = slice(0, sc.pulse_at)
    y_min, y_max = np.asarray(ranges["y_min"]), np.asarray(ranges["y_max"])
    room = np.minimum(y_max - a.y_op, a.y_op - y_min)
    excursion = np.abs(ref.y[before] - a.y_op).max(axis=0)
    factors = [0.5 * room / np.maximum(excursion, 1e-300)]
    if a.q:
        r_min, r_max = np.asarray(ranges["r_min"]), np.asarray(ranges["r_max"])
        r_room = np.minimum(r_max - a.r_op, a.r_op - r_min)
        factors.append(0.5 * r_room / np.maximum(np.abs(sc.r), 1e-300))
    return float(min(1.0, *np.concatenate(factors)))
