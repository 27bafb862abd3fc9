"""A scheduled design (docs/design.md, scheduled law): every point designed and checked as today, the law the C
runs (each point's velocity-form coefficients, interpolated linearly in sigma) checked frozen on a dense grid and
under a moving sigma, and the schema-2 artifact that carries it all."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ...errors import DesignError
from ...shipping.artifact import SCHEDULED_SCHEMA_VERSION, from_dict, matrix_to_json, seal, vector_to_json
from ...shipping.systems import law_coefficients
from ...spec import PlantSpec
from ...synthesis.record import provenance
from .block import COEFFICIENTS, filter_alpha, load_schedule
from .grid import GridCheck, grid_check
from .variation import DEFAULT_BUDGET, RateSpec, VariationCheck, crossing_warning, rate_text, variation_check

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
    tau = -1.0 / np.log(float(grid.radius.max()))  # the slowest closed-loop time constant, in samples
    rate_spec = RateSpec(rate_max=s.rate_max, certified=s.rate_certified, budget=s.certify_budget or DEFAULT_BUDGET)
    variation = variation_check(sched, Ci=spec.Ci, Ts=spec.Ts, tau_samples=tau, spec=rate_spec, sigma=s.sigma)
    data["schedule"]["rate_max"] = variation.rate_max
    data["schedule"]["rate_certified"] = variation.rate_certified
    data["checks"] = _checks(s.sigma, s.points, results, grid, variation)
    warnings += _rate_warnings(spec, variation, tau)
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


def _rate_warnings(spec: PlantSpec, v: VariationCheck, tau: float) -> list[str]:
    """What the design says of sigma's rate beside the record: a spec's rate above the certified one, a rate not
    certified, a certified rate too slow to cross the envelope in reasonable time, and what the limit covers."""
    s, out = spec.schedule, []
    name, proved = s.sigma, v.certified_rate
    if s.rate_max is not None and s.rate_certified and proved is not None and s.rate_max > proved:
        out.append(f"the spec's rate_max of {name}, {s.rate_max:g}/s, is above the certified rate: the law ships "
                   f"{rate_text(v.rate_max, True)}")  # fmt: skip
    if not v.rate_certified:
        out.append(f"rate_max of {name}: {rate_text(v.rate_max, False)}: the spec declared it (rate_certified = "
                   "false); no Lyapunov certificate covers it")  # fmt: skip
    slow = crossing_warning(v, span=float(s.points[-1] - s.points[0]), Ts=spec.Ts, tau_samples=tau, sigma=name)
    if slow:
        out.append(slow)
    if v.rate_max is not None:
        out.append(
            f"the law limits the {name} it uses to {rate_text(v.rate_max, v.rate_certified)}, but only a "
            f"rate-limited reference or a slow external signal keeps the plant's own {name} within that rate"
        )
    return out


def describe_schedule(checks: dict) -> list[str]:
    """The lines ``gainlink design`` and ``analyze`` print for ``checks.schedule``."""
    sigma = checks["sigma"]
    lines = []
    for pt in checks["points"]:
        mg = "; ".join(_margin_text(m) for m in pt["margins"])
        lines.append(f"at {sigma} = {pt['sigma']:g}: closed-loop spectral radius {pt['spectral_radius']:.5f}, {mg}")
    g = checks["grid"]
    lines.append(
        f"between points, at {g['sigma_count']} values of {sigma} ({g['per_interval']} steps per interval; the law "
        f"the C runs): spectral radius at most {g['max_spectral_radius']:.5f} (at {sigma} = {g['worst_sigma']:.4g}), "
        f"gain margin at least +{_db(g['min_gain_margin_up_db'])} dB, phase margin at least "
        f"{_deg(g['min_phase_margin_deg'])}"
    )
    lines += _variation_lines(sigma, checks["variation"])
    return lines


def _variation_lines(sigma: str, v: dict) -> list[str]:
    """The verdict on a moving sigma, each figure with what covers it (docs/design.md, verdicts)."""
    if "frozen" not in v:  # an artifact from before the certified rate
        return [f"moving {sigma}: rate_max {rate_text(v.get('rate_max'), False)} (recorded before certificates of "
                "the rate: not proved)"]  # fmt: skip
    lines = [f"frozen at any {sigma} between the points: stable, certified ({v['frozen']['pieces']} pieces, one "
             "Lyapunov function each, proved in ball arithmetic)"]  # fmt: skip
    cert = v["certificate"]
    if v["common_lyapunov"]:
        proof = f"certified for any rate of {sigma} (one Lyapunov function, margin {cert['margin']:.3g})"
    elif v["certified_rate"] is not None:
        proof = (f"certified for |d{sigma}/dt| <= {v['certified_rate']:.4g}/s (a {sigma}-dependent Lyapunov "
                 f"function, {cert['hull_pieces']} pieces, margin {cert['margin']:.3g})")  # fmt: skip
    else:
        proof = "no rate certified"
    lines.append(f"moving {sigma}: {proof}")
    f = v["falsifier"]
    worst = _path_text(sigma, f["worst"])
    if f["first_growing_rate"] is None:
        found = f"no growing path at {f['rates_tried']} rates up to a one-step crossing (worst: {worst})"
    else:
        found = f"grows at {f['first_growing_rate']:.4g}/s: {worst}"
    lines.append(f"falsifier (periodic {sigma} paths, simulated: not certified): {found}")
    if f["at_rate_max"] is not None:
        lines.append(f"  worst path found at rate_max: {_path_text(sigma, f['at_rate_max'])}")
    lines.append(f"rate_max the law enforces on {sigma}: {rate_text(v['rate_max'], v['rate_certified'])} "
                 f"({v['rate_source']})")  # fmt: skip
    return lines


def _path_text(sigma: str, p: dict) -> str:
    if p["shape"] == "dwell":
        where = (f"held {p['dwell_low']} samples at {p['low']:.4g} and {p['dwell_high']} at {p['high']:.4g}, moving "
                 f"between them at {p['rate']:.4g}/s")  # fmt: skip
    else:
        where = f"swept between {p['low']:.4g} and {p['high']:.4g} at {p['rate']:.4g}/s"
    return f"{sigma} {where}, x{p['growth_per_step']:.5f} per step"


def _margin_text(m: dict) -> str:
    return (
        f"margins at {m['input']}: gain +{_db(m['gain_margin_up_db'])} / -{_db(m['gain_margin_down_db'], neg=True)} dB,"
        f" phase {_deg(m['phase_margin_deg'])}"
    )


def _db(v: float | None, neg: bool = False) -> str:
    return "inf" if v is None else f"{abs(v):.1f}" if neg else f"{v:.1f}"


def _deg(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.1f} deg"
