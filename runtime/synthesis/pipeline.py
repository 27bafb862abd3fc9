"""The observer-based law's design pipeline: discretise -> augment with integrators of the tracked outputs ->
controller gain (DLQR, placement or given) -> observer gain (Kalman, Luenberger or given; predictor or current form)
-> anti-windup gain -> checks of the combined loop (stability, separation, margins, bandwidth) -> the artifact, with
the realisation of the estimate and the compensator's stability, then the law's own implementation check (the float32
fidelity, or a fixed-point law's certificate), sealed. Every Riccati solution comes from python-control (SLICOT
through slycot).

Which law a spec asks for, and so which implementation check runs, is the law's to say: design a spec with
:func:`gainlink.laws.design` (``gl.design``), which asks the spec's law (:func:`gainlink.laws.law_for_spec`)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DesignError
from ..shipping.artifact import from_dict, seal
from ..spec import PlantSpec
from .analysis import complex_pairs, uncontrollable_unstable, unobservable_unstable
from .compensator import CompensatorStability
from .controller import controller_gain
from .deadtime import DeadTimeCheck, dead_time_check
from .discretize import Discretised, augment, discretise
from .implementation import realise
from .loop import closed_loop_poles
from .margins import ChannelMargin, input_margins, loop_bandwidth
from .observer import observer_gain
from .record import Gains, artifact_data

if TYPE_CHECKING:  # the laws' own results (gainlink.laws.fixed, gainlink.laws.scheduled fill them)
    from ..laws.fixed.certificate import FixedPointCertificate
    from ..laws.lq.fidelity import Float32Fidelity
    from ..laws.scheduled.design import ScheduleDesign

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
    float32: Float32Fidelity | Any = None  # None when the check was switched off; a scheduled law's: its sweep
    dead_time: DeadTimeCheck | None = None  # None unless the plant has sampled dead times
    fixed_point: FixedPointCertificate | None = None  # None unless [implementation] numeric is q31 or q15
    schedule: ScheduleDesign | None = None  # a scheduled spec: every point's result and the verdicts; the fields
    # above are then those of the first point


#: The law's own implementation check (:func:`synthesize_lq`): it records its check in ``data["checks"]``, appends
#: its warnings, and returns the :class:`DesignResult` fields it fills (``float32``, ``fixed_point``).
ImplementationCheck = Callable[[dict, PlantSpec, list[str]], dict[str, Any]]


def synthesize_lq(spec: PlantSpec, implementation_check: ImplementationCheck) -> DesignResult:
    """Design the observer-based law of an unscheduled ``spec`` and return the sealed artifact.

    ``implementation_check`` is the law's check of its arithmetic (:data:`ImplementationCheck`): the float32
    fidelity of the float32 law, the certificate of a fixed-point one.

    Raises
    ------
    SpecError
        A design setting is inconsistent with the discretised plant (e.g. the current form with feedthrough).
    DesignError
        The plant is not stabilizable/detectable, weights are not (semi)definite, or the resulting closed loop
        is not stable (naming the part that is not).
    """
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
    data, compensator = realise(data, spec.implementation, warnings)
    checked = implementation_check(data, spec, warnings)
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
        dead_time=dead_time,
        **checked,
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
