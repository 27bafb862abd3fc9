"""A scheduled design (docs/design.md, scheduled law): every point designed and checked as today, the law the C
runs (each point's velocity-form coefficients, interpolated linearly in sigma) checked frozen on a dense grid and
under a moving sigma, and the schema-2 artifact that carries it all."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..errors import DesignError
from ..shipping.artifact import SCHEDULED_SCHEMA_VERSION, from_dict, matrix_to_json, seal, vector_to_json
from ..shipping.scheduled import COEFFICIENTS, filter_alpha, law_coefficients, load_schedule
from ..spec import PlantSpec
from .record import provenance
from .schedule_grid import GridCheck, grid_check
from .schedule_variation import VariationCheck, variation_check

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ScheduleDesign:
    """What a scheduled design found: each point's own design result, the grid check and the variation verdict."""

    points: np.ndarray
    results: list
    grid: GridCheck
    variation: VariationCheck


def synthesize_scheduled(spec: PlantSpec, design_point: Callable) -> tuple[dict, ScheduleDesign, list[str]]:
    """Design every point with ``design_point`` (the unscheduled pipeline), then the scheduled checks.

    Returns the sealed schema-2 artifact dict, the :class:`ScheduleDesign` and the warnings.
    """
    s = spec.schedule
    results, points_data, warnings = [], [], []
    for i, sigma in enumerate(s.points):
        result = _design_at(spec, i, design_point)
        results.append(result)
        warnings += [f"at {s.sigma} = {sigma:g}: {w}" for w in result.warnings]
        points_data.append(_point_record(spec, i, result.artifact))
    data = _artifact_data(spec, points_data, results)
    sched = load_schedule(data, n=spec.plant.n, m=spec.plant.m, p=spec.plant.p, q=spec.q, form=spec.observer.form)
    grid = grid_check(sched, Ci=spec.Ci, Ts=spec.Ts, inputs=spec.plant.inputs)
    variation = variation_check(sched, Ci=spec.Ci, Ts=spec.Ts, spec_rate_max=s.rate_max)
    data["schedule"]["rate_max"] = variation.rate_max
    data["checks"] = _checks(s.sigma, s.points, results, grid, variation)
    if variation.common is None:
        warnings.append(_rate_warning(spec, variation))
    for w in warnings:
        log.warning(w)
    sealed = seal(data)
    from_dict(sealed)  # the artifact must load: schema, coefficients against the design matrices
    return sealed, ScheduleDesign(s.points, results, grid, variation), warnings


def _design_at(spec: PlantSpec, i: int, design_point: Callable):
    """One point, designed as an unscheduled spec (positional checks; its float32 check is the C law's, later)."""
    point = spec.at_point(i)
    point = replace(
        point,
        limits=replace(point.limits, anti_windup="clamp"),
        implementation=replace(point.implementation, float32_check=False),
    )
    try:
        result = design_point(point)
    except DesignError as exc:
        raise DesignError(f"at {spec.schedule.sigma} = {spec.schedule.points[i]:g}: {exc}") from None
    Ki = np.array(result.artifact["Ki"])
    if np.linalg.matrix_rank(Ki) < spec.plant.m:
        raise DesignError(
            f"at {spec.schedule.sigma} = {spec.schedule.points[i]:g}: Ki is rank-deficient; the velocity form needs "
            "integral action that reaches every input (else the frozen loop has a pole at z = 1 and the trim drifts)"
        )
    return result


def _point_record(spec: PlantSpec, i: int, art: dict) -> dict:
    """``schedule.point[i]``: the coefficients the C runs, the design matrices behind them, the trim."""
    a = {k: np.array(art[k], dtype=float) for k in ("Ad", "Bd", "Cd", "Dd", "K", "L", "Ki")}
    M = np.array(art["M"], dtype=float) if "M" in art else None
    coef = law_coefficients(**a, M=M, Ts=spec.Ts, form=spec.observer.form)
    op = spec.schedule.operating_points[i]
    out = {k: matrix_to_json(v) for k, v in (coef | a).items()}
    if M is not None:
        out["M"] = matrix_to_json(M)
    out |= {"u_op": vector_to_json(op.u_op), "y_op": vector_to_json(op.y_op), "plant": art["plant"],
            "design": art["design"]}  # fmt: skip
    if op.x_op is not None:
        out["x_op"] = vector_to_json(op.x_op)
    return out


def _artifact_data(spec: PlantSpec, points_data: list[dict], results: list) -> dict:
    """The schema-2 artifact's content (checks filled in later)."""
    s, first = spec.schedule, results[0].artifact
    return {
        "schema_version": SCHEDULED_SCHEMA_VERSION,
        "name": spec.name,
        "Ts": spec.Ts,
        "n": spec.plant.n,
        "m": spec.plant.m,
        "p": spec.plant.p,
        "q": spec.q,
        "Ci": matrix_to_json(spec.Ci),
        "u_min": vector_to_json(spec.limits.u_min),
        "u_max": vector_to_json(spec.limits.u_max),
        "anti_windup": "velocity",
        "observer_form": spec.observer.form,
        "signals": first["signals"],
        "plant": {"kind": spec.plant.kind},
        "design": {
            "discretization": first["design"]["discretization"],
            "controller": {"method": first["design"]["controller"]["method"], "augmented": True},
            "observer": {"method": first["design"]["observer"]["method"]},
        },
        "checks": {},
        "provenance": provenance(spec),
        "schedule": {
            "sigma": {"name": s.sigma, "source": s.source, "index": s.index},
            "external": list(s.external),
            "points": vector_to_json(s.points),
            "rate_max": s.rate_max,
            "filter_tau": s.filter_tau,
            "filter_alpha": filter_alpha(s.filter_tau, spec.Ts),
            "varying": _varying(points_data),
            "point": points_data,
        },
    }


def _varying(points_data: list[dict]) -> list[str]:
    """The coefficients (and the trim) that differ between points: only those need interpolating in the C."""
    names = COEFFICIENTS + ("u_op",)
    return [k for k in names if any(p[k] != points_data[0][k] for p in points_data[1:])]


def _checks(sigma: str, points: np.ndarray, results: list, grid: GridCheck, variation: VariationCheck) -> dict:
    worst = int(np.argmax([r.artifact["checks"]["spectral_radius"] for r in results]))
    per_point = [
        {"sigma": float(sigma)}
        | {k: r.artifact["checks"][k] for k in ("closed_loop_poles", "spectral_radius", "margins", "compensator")}
        for sigma, r in zip(points, results)
    ]
    return {
        "closed_loop_poles": results[worst].artifact["checks"]["closed_loop_poles"],
        "spectral_radius": float(grid.radius.max()),
        "schedule": {"sigma": sigma, "points": per_point, "grid": grid.to_dict(), "variation": variation.to_dict()},
    }


def _rate_warning(spec: PlantSpec, v: VariationCheck) -> str:
    rate = "not limited" if v.rate_max is None else f"limited to {v.rate_max:.4g} {spec.schedule.sigma}/s"
    return (
        f"no common Lyapunov function: stability is proved only for a slowly moving {spec.schedule.sigma}; the law "
        f"limits the {spec.schedule.sigma} it uses ({rate}, from the {v.rate_max_source}), but only a "
        "rate-limited reference or a slow external signal keeps the plant within that rate"
    )


def describe_schedule(checks: dict) -> list[str]:
    """The lines ``gainlink design`` and ``analyze`` print for ``checks.schedule``."""
    sigma = checks["sigma"]
    lines = []
    for pt in checks["points"]:
        mg = "; ".join(_margin_text(m) for m in pt["margins"])
        lines.append(f"at {sigma} = {pt['sigma']:g}: closed-loop spectral radius {pt['spectral_radius']:.5f}, {mg}")
    g = checks["grid"]
    lines.append(
        f"between points ({g['per_interval']} steps per interval, {g['sigma_count']} values of {sigma}, the law the "
        f"C runs): spectral radius at most {g['max_spectral_radius']:.5f} (at {sigma} = {g['worst_sigma']:.4g}), "
        f"gain margin at least +{_db(g['min_gain_margin_up_db'])} dB, phase margin at least "
        f"{_deg(g['min_phase_margin_deg'])}"
    )
    v = checks["variation"]
    if v["common_lyapunov"]:
        proof = (
            f"a common quadratic Lyapunov function proves stability for any rate of {sigma} "
            f"(margin {v['certificate_margin']:.3g}, {v['solver']})"
        )
    elif v["certified_rate"] is not None:
        proof = (
            f"no common Lyapunov function; a {sigma}-dependent one certifies |d{sigma}/dt| <= "
            f"{v['certified_rate']:.4g}/s"
        )
    else:
        proof = "no Lyapunov certificate found"
    sim = v["simulated_stable_rate"]
    sim_text = "stable at every rate tried" if sim is None else f"stable up to {sim:.4g}/s"
    rate = "not limited" if v["rate_max"] is None else f"{v['rate_max']:.4g}/s"
    lines.append(f"moving {sigma}: {proof}; simulation (ramps and steps across the envelope): {sim_text}")
    lines.append(f"rate_max the law enforces on {sigma}: {rate} ({v['rate_max_source']})")
    return lines


def _margin_text(m: dict) -> str:
    return (
        f"margins at {m['input']}: gain +{_db(m['gain_margin_up_db'])} / -{_db(m['gain_margin_down_db'], neg=True)} dB,"
        f" phase {_deg(m['phase_margin_deg'])}"
    )


def _db(v: float | None, neg: bool = False) -> str:
    return "inf" if v is None else f"{abs(v):.1f}" if neg else f"{v:.1f}"


def _deg(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.1f} deg"
