"""The fixed-point certificate of a design: formats, no overflow, and how far the command can be from the float64
law (docs/design.md, fixed point; the parts: :mod:`gainlink.synthesis.wcpg`, :mod:`.ranges`, :mod:`.formats`,
:mod:`.error`).

What it covers, recorded in ``checks.fixed_point.covers`` (:data:`COVERS`, the words ``design`` prints and the
docs use):

- **no overflow**, for any compensator: every sample within ``[y_min, y_max]`` and reference within
  ``[r_min, r_max]`` (others are clipped to them and flagged), any history, any saturation: the estimate, the
  integrator, the unsaturated command, the command's deviation ``dU`` and every accumulator stay within their
  formats;
- **the headline** (``error.certified``, gated against ``fixed_point_max_error``): the float the C returns against
  the design's float64 law, around the design model, any history with samples and references within their
  declared ranges, initial states, disturbances and noise included, while no input saturates and no sample is
  clipped; under saturation the deviation is measured (the design-time fidelity run), not certified;
- beside it, sharper figures that cover less, each with its scope: from rest at the operating point driven by
  references only (``reference_driven``); against the float64 law with the same quantised coefficients (the
  rounding alone: per step, open loop, closed loop); per step against the design's law;
- the closed loop's stability re-checked with the quantised coefficients.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import numpy as np

from ...errors import DesignError
from ...proof.ball import precision
from ...proof.derived_law import derive
from ...shipping.artifact import Artifact
from .error import (
    Injections,
    InOperation,
    PerStep,
    check_quantised_loop,
    closed_loop_bound,
    coefficient_injections,
    coefficient_terms,
    compensator_radius,
    in_operation_bound,
    open_loop_bound,
    per_step,
    per_step_design,
)
from .formats import Quantised, choose

SCOPE = "while no input saturates and no sample is clipped; under saturation measured, not certified"
COVERS = {
    "no_overflow": "every variable and accumulator within its format for samples in [y_min, y_max] and references "
    "in [r_min, r_max] (others are clipped and flagged), any history, saturated or not, whatever the compensator",
    "certified": "the float the C returns against the design's float64 law, around the design model, for any "
    "history with samples and references within their declared ranges, initial states, disturbances and noise "
    f"included, {SCOPE}",
    "reference_driven": "the same deviation from rest at the operating point, driven by references within their "
    f"ranges only (no initial state, disturbance or noise), {SCOPE}: sharper, covers less",
    "per_step": "the command from the same state (one step, resynchronised) against the design's float64 law, the "
    "state reached by any history in range: every compensator",
    "per_step_rounding": "the command from the same state against the float64 law with the same quantised "
    "coefficients and sample clip (the rounding alone): every compensator",
    "closed_loop": "the float the C returns against the float64 law with the same quantised coefficients, around the "
    "design model, any history in range, initial states and disturbances included, every compensator (integrators "
    f"and unstable compensators included), {SCOPE}",
    "open_loop": "the float the C returns against the float64 law with the same quantised coefficients, both fed "
    "the same samples within their ranges: a stable compensator without integrators only, while no input saturates",
    "coefficients": "the design's law against the quantised one from rest, driven by references within their ranges "
    "(closed loop around the design model) or samples within theirs (open loop) only",
    "float": "every command figure is of the float the C returns, (float)U 2^-f_u: exact in q15, within half a "
    "float32 unit of the largest command word in q31 (error.command_float)",
    "rigour": "peak gains (WCPG) with a verified tail, of matrices formed in ball arithmetic: the float64 rounding of "
    "forming them is covered",
}


@dataclass(frozen=True)
class FixedPointCertificate:
    """A fixed-point law and what is proved about it (module docstring); bounds are in each signal's units.

    ``per_step`` is against the quantised law (the rounding alone), ``per_step_design`` against the design's law;
    ``open_loop`` and ``closed_loop`` are the rounding over time; ``coefficients_*`` the quantisation from rest
    driven by references or samples; ``in_operation`` the headline (:attr:`certified`) with its parts;
    ``injections`` what the coefficients inject into each equation for any history in range."""

    numeric: str
    quantised: Quantised
    per_step: PerStep
    per_step_design: np.ndarray
    open_loop: np.ndarray | None
    closed_loop: np.ndarray
    coefficients_open_loop: np.ndarray | None
    coefficients_closed_loop: np.ndarray
    injections: Injections
    in_operation: InOperation
    loop_radius: float
    compensator_radius: float
    integrators: int
    span: np.ndarray
    max_error: float
    ranges: dict
    names: dict

    @property
    def certified(self) -> np.ndarray:
        """The headline: the command's certified deviation from the design's float64 law per input, in operation
        (``COVERS["certified"]``)."""
        return self.in_operation.total

    @property
    def reference_driven(self) -> np.ndarray:
        """The sharper figure from rest driven by references only (``COVERS["reference_driven"]``): the rounding
        in closed loop (or per step if larger) plus the coefficients' closed-loop term."""
        return np.maximum(self.per_step.u, self.closed_loop) + self.coefficients_closed_loop

    @property
    def fraction(self) -> np.ndarray:
        """:attr:`certified` as a fraction of each input's limit span."""
        return self.certified / self.span

    @property
    def case(self) -> str:
        """Which over-time bound applies to a replay: the compensator open loop, or only the closed loop."""
        if self.open_loop is not None:
            return "open_loop"
        why = "integrators" if self.integrators else "an unstable compensator"
        return f"closed_loop (open loop not certified: {why})"

    @property
    def signature(self) -> str:
        """32-bit signature of the number formats (the C's ``gl_gains_t`` carries it; uploads must match)."""
        g = self.quantised.gains
        body = {"numeric": self.numeric, "formats": g.formats.to_dict(), "accumulators": _acc(g)}
        return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:8]


def _acc(g) -> dict:
    return {"v": g.acc_v.tolist(), "z": g.acc_z.tolist(), "x": g.acc_x.tolist()}


def certify(a: Artifact, ranges: dict, *, numeric: str, max_error: float) -> FixedPointCertificate:
    """Choose the formats of ``a``'s law in ``numeric`` for inputs in ``ranges`` (y_min, y_max, r_min, r_max) and
    prove its bounds.

    Raises
    ------
    DesignError
        An unstable estimator (``F``), an integrator that cannot be bounded, a closed loop that the quantised
        coefficients destabilise, or a certified deviation above ``max_error`` of some input's span (naming the
        remedy).
    """
    with precision():
        cert = FixedPointCertificate(
            numeric=numeric,
            integrators=a.q,
            span=a.u_max - a.u_min,
            max_error=max_error,
            ranges={k: np.asarray(v, dtype=float).tolist() for k, v in ranges.items() if v is not None},
            names={
                "xh": a.signals["states"],
                "u": a.signals["inputs"],
                "y": a.signals["outputs"],
                "r": a.signals["references"],
            },
            **_bounds(a, ranges, numeric),
        )
    _check_max_error(cert)
    return cert


def _bounds(a: Artifact, ranges: dict, numeric: str) -> dict:
    """The formats and every bound of the certificate (its fields but the names and the spans)."""
    qz = choose(derive(a).with_ranges(ranges), numeric)
    design = derive(a, exact=True)
    ideal, h = qz.gains.ideal, qz.rounding
    plant = (a.Ad, a.Bd, a.Cd, a.Dd)
    radius = check_quantised_loop(ideal, plant, numeric)
    coeff_open, coeff_closed = coefficient_terms(design, ideal, plant, ranges)
    rounding = per_step(ideal, h)
    injections = coefficient_injections(design, qz)
    return {
        "quantised": qz,
        "per_step": rounding,
        "per_step_design": per_step_design(design, ideal, rounding, injections),
        "open_loop": open_loop_bound(ideal, h),
        "closed_loop": closed_loop_bound(ideal, plant, h),
        "coefficients_open_loop": coeff_open,
        "coefficients_closed_loop": coeff_closed,
        "injections": injections,
        "in_operation": in_operation_bound(design, plant, qz, injections),
        "loop_radius": radius,
        "compensator_radius": compensator_radius(ideal),
    }


def _check_max_error(cert: FixedPointCertificate) -> None:
    worst = int(np.argmax(cert.fraction))
    if cert.fraction[worst] <= cert.max_error:
        return
    ranges = "narrow the declared ranges (limits.y_min/y_max, r_min/r_max)"
    remedy = f'use numeric = "q31", {ranges}' if cert.numeric == "q15" else f'{ranges}, try realization = "balanced"'
    span, parts = cert.span[worst], cert.in_operation
    raise DesignError(
        f"no {cert.numeric} format meets fixed_point_max_error = {cert.max_error:.3g} on input "
        f"{cert.names['u'][worst]}: certified deviation in operation {cert.fraction[worst]:.3g} of the span "
        f"(rounding {parts.rounding[worst] / span:.3g}, coefficients {parts.coefficients[worst] / span:.3g}; "
        f"from rest driven by references only {cert.reference_driven[worst] / span:.3g}); {remedy}, or raise "
        "fixed_point_max_error"
    )


def certificate_dict(cert: FixedPointCertificate) -> dict:
    """The artifact's ``checks.fixed_point``."""
    qz = cert.quantised
    g = qz.gains

    def vec(x):
        return None if x is None else [float(v) for v in np.asarray(x).ravel()]

    return {
        "numeric": cert.numeric,
        "signature": cert.signature,
        "ranges": cert.ranges,
        "formats": g.formats.to_dict(),
        "accumulators": _acc(g),
        "integers": g.integers(),
        "variables": _variables(cert),
        "accumulator_headroom_bits": {
            k: [float(63 - np.log2(max(b, 1.0))) for b in v] for k, v in qz.acc_bounds.items()
        },
        "error": _error_dict(cert),
        "case": cert.case,
        "covers": dict(COVERS),
        "closed_loop_spectral_radius": cert.loop_radius,
        "compensator_spectral_radius": cert.compensator_radius,
        "wcpg": {"method": qz.bounds.gain.method, "terms": qz.bounds.gain.terms},
    }


def _error_dict(cert: FixedPointCertificate) -> dict:
    """``checks.fixed_point.error``: every figure per input, in its units (scopes: ``covers``)."""

    def vec(x):
        return None if x is None else [float(v) for v in np.asarray(x).ravel()]

    inj = cert.injections
    return {
        "certified": vec(cert.certified),
        "certified_parts": {
            "rounding": vec(cert.in_operation.rounding),
            "coefficients": vec(cert.in_operation.coefficients),
        },
        "fraction_of_span": vec(cert.fraction),
        "max_error": cert.max_error,
        "reference_driven": vec(cert.reference_driven),
        "per_step": vec(cert.per_step_design),
        "per_step_rounding": vec(cert.per_step.u),
        "open_loop": vec(cert.open_loop),
        "closed_loop": vec(cert.closed_loop),
        "coefficients_closed_loop": vec(cert.coefficients_closed_loop),
        "coefficients_open_loop": vec(cert.coefficients_open_loop),
        "injections": {k: vec(getattr(inj, k)) for k in ("v", "x", "z", "u_op", "y_op", "xh0", "z0")},
        "command_float": vec(cert.quantised.rounding.c),
    }


def _variables(cert: FixedPointCertificate) -> list[dict]:
    """Each state-word variable's format, certified bound and headroom."""
    qz, names = cert.quantised, cert.names
    b, fm = qz.bounds, qz.gains.formats
    rows = []
    groups = (
        ("xh", names["xh"], b.xh, fm.xh),
        ("z", names["r"], b.z, fm.z),
        ("v", names["u"], np.maximum(b.v, b.w), fm.v),
    )
    for group, labels, bounds, formats in groups:
        for label, bound, f in zip(labels, bounds, formats):
            rows.append(
                {
                    "name": f"{group}[{label}]",
                    **f.to_dict(),
                    "bound": float(bound),
                    "headroom_bits": float(f.headroom_bits(float(bound))),
                }
            )
    for group, labels, formats in (("y", names["y"], fm.y), ("r", names["r"], fm.r), ("u", names["u"], fm.u)):
        rows.extend({"name": f"{group}[{label}]", **f.to_dict()} for label, f in zip(labels, formats))
    return rows


def describe(cert: FixedPointCertificate) -> list[str]:
    """Lines for ``gainlink design``: the formats, no overflow, the headline with its scope, and beside it the
    sharper figures with theirs (the words of :data:`COVERS`)."""
    qz = cert.quantised
    lines = [
        f"fixed point {cert.numeric} (signature {cert.signature}): formats "
        + ", ".join(f"{v['name']} {v['q']}" for v in _variables(cert))
    ]
    lines.append(
        "  no overflow for samples and references within their declared ranges (estimate bound by WCPG, "
        f"{qz.bounds.gain.method} certificate, {qz.bounds.gain.terms} terms); least headroom "
        f"{min(v['headroom_bits'] for v in _variables(cert) if 'headroom_bits' in v):.2f} bits"
    )
    lines.append(f"  |u - u64| certified (gated against fixed_point_max_error): {COVERS['certified']}")
    parts = cert.in_operation
    for i, name in enumerate(cert.names["u"]):
        lines.append(
            f"    {name}: {cert.certified[i]:.3g} = {cert.fraction[i]:.3g} of the span (max {cert.max_error:.3g}; "
            f"rounding {parts.rounding[i]:.3g}, coefficients {parts.coefficients[i]:.3g})"
        )
    lines.append(
        "  beside it, covering less: from rest driven by references only; per step (resynchronised) against the "
        "design's law; the rounding alone, against the float64 law with the quantised coefficients"
    )
    for i, name in enumerate(cert.names["u"]):
        ol = "n/a" if cert.open_loop is None else f"{cert.open_loop[i]:.3g}"
        lines.append(
            f"    {name}: from rest {cert.reference_driven[i]:.3g}; per step {cert.per_step_design[i]:.3g}; rounding "
            f"alone: per step {cert.per_step.u[i]:.3g}, closed loop {cert.closed_loop[i]:.3g}, open loop {ol}"
        )
    lines.append(f"  over time: {cert.case}; under saturation measured, not certified")
    return lines
