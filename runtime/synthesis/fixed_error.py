"""How far the fixed-point command can be from the float64 law, from the rounding at every quantisation point
(docs/design.md, fixed point: the command's error).

The float64 law compared against has the same quantised coefficients, operating point and limits, and clips its
samples to the same ranges (:class:`~gainlink.proof.derived_law.DerivedLoop` on ``FixedGains.ideal``); the
integer law differs from it only by rounding: each sample and reference quantised (half a unit of its format),
each output of a sum of products rounded once (half a unit of ``v``, ``u``, ``z``, ``xh``), and the float the C
returns, ``(float)U`` times a power of two (exact in q15; within half a float32 unit of the largest command word
in q31: ``c``, at the plant's input). Three bounds:

- **per step**, from the same state (the one-step, resynchronised check): ``|du| <= |Ky| h_y + h_v + h_u + c``,
  for every compensator. The next state likewise (the integrator with clamping: when both laws take the same
  clamping decision).
- **open loop over time**, for a stable compensator without integrators, while no input saturates: the rounding
  drives the compensator's own dynamics ``F + G Kx``; the WCPG of that error system bounds the command error for
  ever.
- **closed loop around the design model**, while no input saturates and no sample is clipped: the rounding drives
  the loop (plant model + law), stable by design and re-checked with the quantised coefficients; its WCPG bounds
  the command error for ever, whatever the compensator (integrators and unstable compensators included).

Coefficient quantisation is a separate term: the WCPG of the difference between the design's law and the
quantised one, driven by the same inputs (open loop: the samples within their ranges; closed loop: the
references within theirs, with the rounded operating point as constant offsets).

Every peak gain is of matrices formed in balls (:mod:`gainlink.proof.ball`), through
:func:`~.wcpg.wcpg_ball`: the float64 rounding of forming them is covered.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DesignError
from ..proof.ball import abs_upper, balls, mid, precise
from ..proof.derived_law import DerivedLaw
from .fixed_loops import LinearSystem, closed_loop, difference, open_loop
from .fixed_ranges import Rounding, centre_half
from .wcpg import spectral_radius, wcpg_ball


@dataclass(frozen=True)
class PerStep:
    """One-step bounds against the quantised law (same state before the step): the command ``u`` (m, the float
    the C returns), next ``xh`` (n) and ``z`` (q)."""

    u: np.ndarray
    xh: np.ndarray
    z: np.ndarray


def per_step(law: DerivedLaw, h: Rounding) -> PerStep:
    """The resynchronised bounds (module docstring)."""
    dv = np.abs(law.Ky) @ h.y + h.v
    du = dv + h.u + h.c
    xh = np.abs(law.G) @ (dv + h.u) + np.abs(law.Ly) @ h.y + h.x
    kaw = np.abs(law.Kaw) @ dv if law.anti_windup == "backcalc" else 0.0
    z = np.abs(law.Tr) * h.r + np.abs(law.Ty) @ h.y + kaw + h.z
    up = 1 + 1e-12
    return PerStep(u=du * up, xh=xh * up, z=np.asarray(z) * up)


def _rounding_weights(h: Rounding, *, loop: bool) -> dict[str, np.ndarray]:
    weights = {"ny": h.y, "rv": h.v, "ru": h.u, "rx": h.x, "d": h.c}
    if loop:
        weights |= {"nr": h.r, "rz": h.z}
    return weights


def _bound(system: LinearSystem, weights: dict[str, np.ndarray], what: str) -> np.ndarray:
    B, D = system.columns(weights)
    return wcpg_ball(system.A, B, system.C, D, what=what).total


def compensator_radius(law: DerivedLaw) -> float:
    """Spectral radius of the compensator without its integrators, ``F + G Kx`` (an estimate)."""
    return spectral_radius(mid(law.F) + mid(law.G) @ mid(law.Kx))


@precise
def open_loop_bound(law: DerivedLaw, h: Rounding) -> np.ndarray | None:
    """The open-loop bound, or None when it does not apply (integrators, or an unstable compensator)."""
    if law.q or not compensator_radius(law) < 1.0:
        return None
    return _bound(open_loop(law), _rounding_weights(h, loop=False), "the compensator's rounding error")


def check_quantised_loop(law: DerivedLaw, plant: tuple, numeric: str) -> float:
    """The closed loop's spectral radius with the quantised coefficients; DesignError when it is not stable."""
    radius = spectral_radius(mid(closed_loop(law, plant).A))
    if not radius < 1.0:
        raise DesignError(
            f"the closed loop is unstable with the {numeric} coefficients (spectral radius {radius:.6g} >= 1): "
            'use numeric = "q31"' + ("" if numeric == "q15" else " with narrower declared ranges")
        )
    return radius


@precise
def closed_loop_bound(law: DerivedLaw, plant: tuple, h: Rounding) -> np.ndarray:
    """The closed-loop bound (module docstring)."""
    system = closed_loop(law, plant)
    return _bound(system, _rounding_weights(h, loop=True), "the closed loop with the quantised coefficients")


@precise
def coefficient_terms(
    design: DerivedLaw, ideal: DerivedLaw, plant: tuple, ranges: dict
) -> tuple[np.ndarray | None, np.ndarray]:
    """``(open loop or None, closed loop)`` bounds of the command difference between the design's law (in balls)
    and the quantised one from rest, driven by references (open loop: samples) within ``ranges`` only (module
    docstring). ``ranges`` holds the real y_min/y_max (p) and r_min/r_max (q)."""
    offsets = {"nop": _gap(design.y_op, ideal.y_op), "d": _gap(ideal.u_op, design.u_op)}
    closed = difference(closed_loop(design, plant), closed_loop(ideal, plant), shared=("r",))
    weights = dict(offsets)
    if design.q:
        r_op = -(balls(design.Ty) @ balls(design.y_op)) / balls(design.Tr)  # Ci y_op
        centre, half = centre_half((balls(ranges["r_min"]) - r_op, balls(ranges["r_max"]) - r_op))
        closed = _with_centre(closed, "r", centre)
        weights |= {"r": abs_upper(half), "r_centre": np.ones(1)}
    closed_bound = _bound(closed, weights, "the difference of the design's and the quantised closed loops")
    if design.q or not (compensator_radius(design) < 1.0 and compensator_radius(ideal) < 1.0):
        return None, closed_bound
    y_op = balls(design.y_op)
    centre, half = centre_half((balls(ranges["y_min"]) - y_op, balls(ranges["y_max"]) - y_op))
    diff = _with_centre(difference(open_loop(design), open_loop(ideal), shared=("ny",)), "ny", centre)
    weights = offsets | {"ny": abs_upper(half), "ny_centre": np.ones(1)}
    return _bound(diff, weights, "the difference of the design's and the quantised compensators"), closed_bound


def _gap(x, y) -> np.ndarray:
    """``|x - y|`` rounded up (exact differences of float64 numbers)."""
    return abs_upper(balls(x) - balls(y))


def _with_centre(system: LinearSystem, name: str, centre: np.ndarray) -> LinearSystem:
    """``system`` with one more input column, ``name_centre``: the constant ``centre`` of input ``name``."""
    B = dict(system.B, **{f"{name}_centre": system.B[name] @ centre[:, None]})
    D = dict(system.D, **{f"{name}_centre": system.D[name] @ centre[:, None]})
    return LinearSystem(A=system.A, B=B, C=system.C, D=D)
