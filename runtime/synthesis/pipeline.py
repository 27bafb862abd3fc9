"""The design pipeline: discretise -> augment with integrators of the tracked outputs -> controller gain (DLQR,
placement or given) -> observer gain (Kalman, Luenberger or given; predictor or current form) -> anti-windup gain
-> checks of the combined loop (stability, separation, margins, bandwidth) -> the artifact, with the
implementation choices and their checks, sealed. Every Riccati solution comes from python-control (SLICOT through
slycot)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..errors import DesignError
from ..proof.fidelity import Float32Fidelity
from ..shipping.artifact import from_dict, seal
from ..spec import PlantSpec
from .analysis import complex_pairs, uncontrollable_unstable, unobservable_unstable
from .compensator import CompensatorStability
from .controller import controller_gain
from .deadtime import DeadTimeCheck, dead_time_check
from .discretize import Discretised, augment, discretise
from .fixed_point import FixedPointCertificate
from .implementation import implement
from .loop import closed_loop_poles
from .margins import ChannelMargin, input_margins, loop_bandwidth
from .observer import observer_gain
from .record import Gains, artifact_data
from .schedule import ScheduleDesign, synthesize_scheduled

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DesignResult:
    """A finished design: the sealed artifact dict and the numbers behind its checks."""

    artifact: dict
    controller_poles: np.ndarray
    observer_poles: np.ndarray
    closed_loop_poles: np.ndarray
    margins: list[ChannelMargin]
    warnings: list[str] = field(default_factory=list)
    compensator: CompensatorStability | None = None
    float32: Float32Fidelity | None = None  # None when the check was switched off
    dead_time: DeadTimeCheck | None = None  # None unless the plant has sampled dead times
    fixed_point: FixedPointCertificate | None = None  # None unless [implementation] numeric is q31 or q15
    schedule: ScheduleDesign | None = None  # a scheduled spec: every point's result and the verdicts; the fields
    # above are then those of the first point


def synthesize(spec: PlantSpec) -> DesignResult:
    """Design the controller and observer a spec asks for and return the sealed artifact.

    Raises
    ------
    SpecError
        A design setting is inconsistent with the discretised plant (e.g. the current form with feedthrough).
    DesignError
        The plant is not stabilizable/detectable, weights are not (semi)definite, or the resulting closed loop
        is not stable (naming the part that is not); with a schedule, also a point, the grid between points, or
        the LMI solver.
    """
    if spec.schedule is not None:
        return _scheduled(spec)
    warnings: list[str] = []
    d = discretise(spec)
    Aa, Ba = augment(d, spec.Ci, spec.Ts)
    _check_feasible(d, Aa, Ba, spec.q)
    Ka, controller_record = controller_gain(spec, Aa, Ba, warnings)
    L, M, observer_record = observer_gain(spec, d)
    n = spec.plant.n
    gains = Gains(K=Ka[:, :n], Ki=Ka[:, n:], L=L, M=M, Kaw=_anti_windup_gain(spec, Ka[:, n:], controller_record),
                  Ci=spec.Ci)  # fmt: skip
    cl_poles, radius = closed_loop_poles(d, Aa - Ba @ Ka, gains.loop(spec))
    ctrl_poles = np.linalg.eigvals(Aa - Ba @ Ka)
    margins = input_margins(d, inputs=spec.plant.inputs, **gains.loop(spec))
    _check_sampling(margins, ctrl_poles, spec.Ts, warnings)
    checks = {
        "closed_loop_poles": complex_pairs(sorted(cl_poles, key=lambda z: (abs(z), z.imag))),
        "spectral_radius": radius,
        "margins": [dict(mg.__dict__) for mg in margins],
    }
    record = {"discretization": d.method, "controller": controller_record, "observer": observer_record}
    data = artifact_data(spec, d, gains, design_record=record, checks=checks)
    data, compensator, fidelity, fixed = implement(data, spec.implementation, warnings, ranges=_ranges(spec))
    dead_time = _dead_time(spec, data, warnings)
    for w in warnings:
        log.warning(w)
    return DesignResult(
        artifact=seal(data),
        controller_poles=ctrl_poles,
        observer_poles=np.linalg.eigvals(d.A - L @ d.C),
        closed_loop_poles=cl_poles,
        margins=margins,
        warnings=warnings,
        compensator=compensator,
        float32=fidelity,
        dead_time=dead_time,
        fixed_point=fixed,
    )


def _ranges(spec: PlantSpec) -> dict:
    """The declared ranges of samples and references (None where not declared)."""
    lim = spec.limits
    return {"y_min": lim.y_min, "y_max": lim.y_max, "r_min": lim.r_min, "r_max": lim.r_max}


def _scheduled(spec: PlantSpec) -> DesignResult:
    """Every point through :func:`synthesize`, then the scheduled checks (:mod:`.schedule`)."""
    artifact, design, warnings = synthesize_scheduled(spec, synthesize)
    first = design.results[0]
    return DesignResult(
        artifact=artifact,
        controller_poles=first.controller_poles,
        observer_poles=first.observer_poles,
        closed_loop_poles=first.closed_loop_poles,
        margins=first.margins,
        warnings=warnings,
        compensator=first.compensator,
        schedule=design,
    )


def _check_feasible(d: Discretised, Aa: np.ndarray, Ba: np.ndarray, q: int) -> None:
    """Stabilizable, detectable, and (with integral action) the augmented plant stabilizable: else DesignError."""
    bad = uncontrollable_unstable(d.A, d.B, discrete=True)
    if bad:
        raise DesignError(f"plant is not stabilizable: unstable mode(s) {_fmt_list(bad)} are uncontrollable")
    bad = unobservable_unstable(d.A, d.C, discrete=True)
    if bad:
        raise DesignError(f"plant is not detectable: unstable mode(s) {_fmt_list(bad)} are unobservable")
    if q:
        bad = uncontrollable_unstable(Aa, Ba, discrete=True)
        if bad:
            raise DesignError(
                "integral action is not feasible: the tracked outputs cannot be driven to a constant "
                f"reference (augmented modes {_fmt_list(bad)} uncontrollable; a plant zero at s=0 / z=1?)"
            )


def _anti_windup_gain(spec: PlantSpec, Ki: np.ndarray, record: dict) -> np.ndarray:
    """Kaw: -aw_gain pinv(Ki) for back-calculation (recorded in the controller record), zeros otherwise."""
    q, m = spec.q, spec.plant.m
    if not (q and spec.limits.anti_windup == "backcalc"):
        return np.zeros((q, m))
    record["aw_gain"] = spec.integral.aw_gain
    return -spec.integral.aw_gain * np.linalg.pinv(Ki)


def _check_sampling(margins: list[ChannelMargin], ctrl_poles: np.ndarray, Ts: float, warnings: list[str]) -> None:
    bandwidth = loop_bandwidth(margins, ctrl_poles, Ts)
    if (2 * np.pi / Ts) < 10 * bandwidth:
        warnings.append(
            f"sampling at {2 * np.pi / Ts:.3g} rad/s is less than 10x the closed-loop bandwidth {bandwidth:.3g} rad/s"
        )


def _dead_time(spec: PlantSpec, data: dict, warnings: list[str]) -> DeadTimeCheck | None:
    """The law against the exact sampled dead times of a transfer-function spec (:mod:`.deadtime`), recorded in
    ``checks.dead_time``; None when the spec has none."""
    check = dead_time_check(spec, from_dict(seal(data)))
    if check is not None:
        data["checks"]["dead_time"] = check.to_dict()
        if not check.stable:
            warnings.append(check.warning())
    return check


def _fmt_list(values) -> str:
    return ", ".join(
        f"{complex(v).real:.4g}{complex(v).imag:+.4g}j" if abs(complex(v).imag) > 1e-12 else f"{complex(v).real:.4g}"
        for v in values
    )
