"""Trim an FMU at each point of a schedule and write the scheduled spec (``gainlink linearize FMU --schedule
NAME=v1,v2,...``).

At each value of the scheduling variable the FMU is *trimmed*, not only evaluated: the states and inputs that
are not held are solved for so that ``dx/dt = 0`` with the scheduling variable at its value, by Newton's method
(least-norm steps when there are more unknowns than equations, so the trim stays near its start), each
evaluation a :func:`~gainlink.hil.plants.linearize.linearize` at the current guess (its Jacobians are Newton's).
The scheduling variable may be a state (held there), an output (an equation ``y = value``) or a parameter such
as a payload mass (set; sigma is then an external signal of the spec). Values given with ``--at`` are held at
every point. Each point starts from the previous point's trim (continuation along the envelope).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from gainlink.errors import PlantError, SpecError
from gainlink.fileio import atomic_write_text, read_toml

from . import toml_write
from .linearize import Linearization, fmu_path, linearize
from .point_fit import PointFit, fit_schedule, shared_record

log = logging.getLogger(__name__)

TOLERANCE = 1e-10  # on the residual, relative to the model's scale
ITERATIONS = 40
NUDGE = 1e-2  # relative step given to an unknown whose Jacobian column is zero at the guess
HALVINGS = 30


@dataclass(frozen=True)
class Trim:
    """One trimmed point: sigma's value, the linearisation there, Newton's iterations and final residual."""

    sigma: float
    lin: Linearization
    iterations: int
    residual: float


def solve(evaluate, z0: np.ndarray, *, scale: float = 1.0) -> tuple[np.ndarray, int, float]:
    """Damped Newton on ``evaluate(z) -> (residual, Jacobian)``: least-norm steps (an unknown whose column is zero
    at the guess is moved up by :data:`NUDGE` instead), halved until the residual shrinks and the point is one the
    FMU accepts; ``(z, iterations, |residual|)``, PlantError when it does not converge."""
    z = np.asarray(z0, dtype=float).copy()
    g, J = evaluate(z)
    norm = float(np.max(np.abs(g), initial=0.0))
    for k in range(1, ITERATIONS + 1):
        if norm <= TOLERANCE * scale:
            return z, k, norm
        step = np.linalg.lstsq(J, g, rcond=None)[0]
        dead = ~np.any(J != 0.0, axis=0)  # an unknown with no effect here (a thrust k u^2 at u = 0): nudge it
        if dead.any():
            step = np.where(dead, -NUDGE * np.maximum(1.0, np.abs(z)), step)
        z, g, J, norm = _damped(evaluate, z, step, norm, force=bool(dead.any()))
    raise PlantError(f"trim did not converge (residual {norm:.3g} after {ITERATIONS} Newton steps)")


def _damped(evaluate, z, step, norm: float, *, force: bool):
    """The first of ``z - step``, ``z - step / 2``, ... that the FMU accepts and that lowers the residual (any
    accepted one when ``force``: a nudge may not lower it)."""
    alpha = 1.0
    for _ in range(HALVINGS):
        trial = z - alpha * step
        try:
            g, J = evaluate(trial)
        except PlantError:  # e.g. outside the range the FMU declares for an input
            alpha /= 2
            continue
        new = float(np.max(np.abs(g), initial=0.0))
        if np.isfinite(new) and (force or new < norm):
            return trial, g, J, new
        alpha /= 2
    raise PlantError(f"trim did not converge (no Newton step lowers the residual {norm:.3g})")


def trim_point(fmu: str | Path, *, sigma: str, value: float, at: Mapping[str, float], start: dict | None = None,
               inputs=None, outputs=None, method: str = "auto") -> Trim:  # fmt: skip
    """Trim the FMU with ``sigma`` at ``value`` and the ``at`` values held; ``start`` (name -> value) is the first
    guess of the unknown states and inputs (default: the FMU's start values)."""
    probe = _quiet(lambda: linearize(fmu, at=dict(at), inputs=inputs, outputs=outputs, method=method))
    held = _held(probe, sigma, at)
    names = [s for s in probe.states if s not in held] + [u for u in probe.inputs if u not in held]
    guess = {**dict(zip(probe.states, probe.x0)), **dict(zip(probe.inputs, probe.u0)), **(start or {})}
    fixed = {**at, **({sigma: value} if sigma not in probe.outputs or sigma in probe.states else {})}
    last: dict = {}

    def evaluate(z: np.ndarray):
        point = {**fixed, **dict(zip(names, z))}
        lin = _quiet(lambda: linearize(fmu, at=point, inputs=inputs, outputs=outputs, method=method))
        last["lin"] = lin
        return _residual(lin, names, sigma, value)

    scale = 1.0 + float(np.max(np.abs(np.hstack([probe.A, probe.B])), initial=0.0))
    z, k, res = solve(evaluate, np.array([guess[n] for n in names]), scale=scale)
    evaluate(z)
    return Trim(sigma=float(value), lin=last["lin"], iterations=k, residual=res)


def _held(lin: Linearization, sigma: str, at: Mapping[str, float]) -> set[str]:
    """The states and inputs that are not unknowns: those given in ``at``, and sigma when it is a state."""
    if sigma in lin.inputs:
        raise PlantError(f"--schedule {sigma}: an input is what the trim solves for; schedule on an output, a state "
                         "or a parameter")  # fmt: skip
    return set(at) | ({sigma} if sigma in lin.states else set())


def _residual(lin: Linearization, names: list[str], sigma: str, value: float) -> tuple[np.ndarray, np.ndarray]:
    """``dx/dt`` (and ``y_sigma - value`` when sigma is an output and not a state) and its Jacobian in the
    unknowns."""
    cols = [("x", lin.states.index(n)) if n in lin.states else ("u", lin.inputs.index(n)) for n in names]
    pick = lambda Mx, Mu: np.array([Mx[:, j] if kind == "x" else Mu[:, j] for kind, j in cols]).T  # noqa: E731
    g, J = [lin.dx0], [pick(lin.A, lin.B).reshape(lin.A.shape[0], len(names))]
    if sigma in lin.outputs and sigma not in lin.states:
        i = lin.outputs.index(sigma)
        g.append([lin.y0[i] - value])
        J.append(pick(lin.C[i : i + 1], lin.D[i : i + 1]).reshape(1, len(names)))
    return np.concatenate(g), np.vstack(J)


# Where linearize says a point is not an equilibrium: the operating point (linearize) and the FMU's start point,
# moved to the equilibrium with the inputs held (jacobian). Every probe and Newton guess of a trim is such a point,
# and the FMU's start point is the same for each value of a schedule: not news, once per point.
_EQUILIBRIUM_LOGGERS = ("gainlink.hil.plants.linearize", "gainlink.hil.plants.jacobian")


def _quiet(fn):
    """Run ``fn`` without linearize's "not an equilibrium" messages (every Newton guess is one)."""
    loggers = [logging.getLogger(name) for name in _EQUILIBRIUM_LOGGERS]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.ERROR)
    try:
        return fn()
    finally:
        for logger, level in zip(loggers, levels):
            logger.setLevel(level)


def trim_schedule(fmu, *, sigma: str, values: Sequence[float], at: Mapping[str, float] | None = None,
                  inputs=None, outputs=None, method: str = "auto") -> list[Trim]:  # fmt: skip
    """Trim at each value, each from the previous trim (continuation)."""
    if len(values) < 2 or np.any(np.diff(values) <= 0):
        raise SpecError("--schedule needs at least two strictly increasing values")
    trims, start = [], None
    for v in values:
        t = trim_point(fmu, sigma=sigma, value=float(v), at=dict(at or {}), start=start, inputs=inputs,
                       outputs=outputs, method=method)  # fmt: skip
        start = {**dict(zip(t.lin.states, t.lin.x0)), **dict(zip(t.lin.inputs, t.lin.u0))}
        log.info("trimmed %s = %g in %d Newton steps (residual %.2g)", sigma, v, t.iterations, t.residual)
        trims.append(t)
    return trims


def _signal(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return s if re.match(r"[A-Za-z_]", s) else f"s_{s}"


def schedule_spec_dict(trims: list[Trim], *, sigma: str, Ts: float, name: str, template: Mapping | None) -> dict:
    """The scheduled spec: ``[plant]`` (kind, names), ``[schedule]`` with one ``[[schedule.plant]]`` per trim,
    and the design sections from ``template`` or neutral defaults (integral action on every input)."""
    lin0 = trims[0].lin
    outputs = [_signal(s) for s in lin0.outputs]
    external = [] if sigma in lin0.outputs else [_signal(sigma)]
    points = [{"A": t.lin.A.tolist(), "B": t.lin.B.tolist(), "C": t.lin.C.tolist(), "D": t.lin.D.tolist()}
              | {k: [float(v) for v in getattr(t.lin, a)] for k, a in (("u_op", "u0"), ("y_op", "y0"), ("x_op", "x0"))}
              for t in trims]  # fmt: skip
    data = {
        "name": name,
        "Ts": float(Ts),
        "discretization": "zoh",
        "plant": {
            "kind": "continuous",
            "states": [_signal(s) for s in lin0.states],
            "inputs": [_signal(s) for s in lin0.inputs],
            "outputs": outputs,
        },
        "schedule": {
            "sigma": _signal(sigma),
            "external": external,
            "points": [t.sigma for t in trims],
            "plant": points,
        },
    }
    data.update(_design_sections(template, trims, outputs))
    return data


def _design_sections(template: Mapping | None, trims: list[Trim], outputs: list[str]) -> dict:
    if template is not None:
        return {k: template[k] for k in ("controller", "integral", "observer", "limits") if k in template}
    n, m, p = trims[0].lin.A.shape[0], trims[0].lin.B.shape[1], trims[0].lin.C.shape[0]
    u = np.array([t.lin.u0 for t in trims])
    return {
        "controller": {"method": "lqr", "Q_diag": [1.0] * n, "R_diag": [1.0] * m},
        "integral": {"outputs": outputs[:m], "Q_diag": [1.0] * min(m, p)},
        "observer": {"method": "kalman", "form": "predictor", "W_diag": [1e-4] * n, "V_diag": [1e-6] * p},
        "limits": {
            "u_min": (u.min(axis=0) - 1e3).tolist(),
            "u_max": (u.max(axis=0) + 1e3).tolist(),
            "anti_windup": "velocity",
        },
    }


@dataclass(frozen=True)
class ScheduleWritten:
    """What ``linearize --schedule`` wrote: the trims and each point's fit (:mod:`.point_fit`)."""

    trims: list[Trim]
    fits: list[PointFit]

    def to_json(self) -> dict:
        """``linearize --schedule --json``: sigma, per point its value, Newton's figures and its fit record;
        and the shared ``[linearization]`` record."""
        return {
            "sigma": self.fits[0].sigma,
            "points": [
                {"sigma": t.sigma, "iterations": t.iterations, "residual": t.residual, **f.record()}
                for t, f in zip(self.trims, self.fits)
            ],
            "linearization": shared_record(self.fits),
        }


def trim_schedule_to_spec(*, fmu, sigma: str, values: Sequence[float], at: Mapping[str, float], out: Path, Ts: float,
                          name: str | None = None, inputs=None, outputs=None, method: str = "auto",
                          template: Path | None = None, interface: str = "auto") -> ScheduleWritten:  # fmt: skip
    """Trim at every value, check that the spec designs' parser takes it, fit each point's model to the FMU
    (:mod:`.point_fit`; a poor fit warns naming the point) and write it atomically."""
    from gainlink.spec import parse_spec

    if not Ts > 0:
        raise SpecError("--Ts must be positive")
    if interface not in ("auto", "cs", "me"):
        raise PlantError(f"linearize: --interface must be auto, cs or me, not {interface!r}")
    trims = trim_schedule(fmu, sigma=sigma, values=values, at=at, inputs=inputs, outputs=outputs, method=method)
    tmpl = read_toml(template, what="template spec", error=SpecError)[0] if template is not None else None
    spec_name = name or re.sub(r"[^A-Za-z0-9_]", "_", trims[0].lin.model_name)
    data = schedule_spec_dict(trims, sigma=sigma, Ts=Ts, name=spec_name, template=tmpl)
    parse_spec(data, source=str(out))  # refuse to write a spec design would not take (e.g. a trim outside limits)
    fits = fit_schedule(trims, sigma=sigma, path=fmu_path(fmu), Ts=Ts, interface=interface)
    data["linearization"] = shared_record(fits)
    for point, f in zip(data["schedule"]["plant"], fits):
        point.update(f.record())
    parse_spec(data, source=str(out))
    atomic_write_text(out, toml_write.dumps(data, header=_header(trims, fits, sigma=sigma, at=at, template=tmpl)))
    return ScheduleWritten(trims=trims, fits=fits)


def _header(trims: list[Trim], fits: list[PointFit], *, sigma: str, at: Mapping[str, float], template) -> str:
    """The comment at the top of the scheduled spec: where it came from, what was held, and the fit per point."""
    poor = [f"{f.value:g}" for f in fits if f.validity.fit.poor]
    return (
        f"Scheduled on {sigma} by gainlink linearize --schedule: FMU {trims[0].lin.model_name} trimmed at "
        f"{', '.join(f'{t.sigma:g}' for t in trims)} ({trims[0].lin.method}); held: "
        f"{', '.join(f'{k} = {v:g}' for k, v in at.items()) or 'nothing else'}.\n"
        f"Each point's model is fitted to the FMU at Ts = {fits[0].validity.fit.Ts:g} s through "
        f"{fits[0].validity.choice.interface} (its [[schedule.plant]] fit): "
        + (f"POOR at {sigma} = {', '.join(poor)} (see fit_warning).\n" if poor else "good at every point.\n")
        + (
            "Design sections copied from the template spec."
            if template is not None
            else "Design sections are neutral defaults: edit weights, noise and limits before designing."
        )
    )
