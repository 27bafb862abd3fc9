"""How far the fixed-point command can be from the float64 laws (docs/design.md, fixed point: the command's error).

Two laws are compared against. The **design's law** (its float64 coefficients, exactly: formed in balls,
:func:`~gainlink.proof.derived_law.derive` with ``exact=True``), what the headline is about; and the float64 law
with the **same quantised coefficients**, operating point and limits, clipping its samples to the same ranges
(:class:`~gainlink.proof.derived_law.DerivedLoop` on ``FixedGains.ideal``), from which the integer law differs
only by rounding: each sample and reference quantised (half a unit of its format), each output of a sum of
products rounded once (half a unit of ``v``, ``u``, ``z``, ``xh``), and the float the C returns, ``(float)U``
times a power of two (exact in q15; within half a float32 unit of the largest command word in q31: ``c``).

- **in operation (the headline)**, against the design's law, around the design model, for any history with
  samples and references within their declared ranges, initial states, disturbances and noise included, while no
  input saturates and no sample is clipped. Run the integer law and the design's law as twin loops around the
  design model sharing the initial plant state, disturbances, references and noise. Written with the design's
  coefficients, the integer law is the design's law plus injections: the roundings ``h``, and
  ``zeta = dK (xh, z, dy, du, r)`` with ``dK`` the quantised coefficients minus the design's, each factor one of
  the integer law's own signals, whose range the certificate proves for any history (:mod:`.ranges`). The
  state difference obeys ``e+ = A_cl e + B_h h + B_zeta zeta`` (the design's closed loop): the initial plant
  state, disturbances and noise cancel; the quantised initial estimate and integrator enter as one injection
  before the first step; the rounded operating point as constant offsets. The WCPG of that system bounds the
  command's difference. What ``dF xh + dG du + dLy dy`` and ``dKx xh + dKy dy`` inject is the output of the
  integer law's estimate recursion (the one that bounds its range, driven by ``du`` and ``dy`` within the limits
  and ranges), so the two are taken as one system in cascade (:func:`in_operation_bound`); the rest is bounded as
  signals: ``|dKz|`` times the integrator's bound, the integrators' own ``dTr r + dTy y`` over the ranges exactly.
  Each injection's own peak (:func:`coefficient_injections`) is recorded and bounds the per-step term.
- **per step** (from the same state, resynchronised), for every compensator: against the quantised law
  ``|Ky| h_y + h_v + h_u + c``; against the design's law that plus the coefficient term of the command's sum
  (``zeta_v``, ``|Ky| |d y_op|``, ``|d u_op|``) and the limits' rounding.
- **open loop over time**, against the quantised law, for a stable compensator without integrators, while no input
  saturates: the rounding drives the compensator's own dynamics ``F + G Kx``.
- **closed loop around the design model**, against the quantised law: the rounding drives the loop (stable by
  design and re-checked with the quantised coefficients), any history in range, unsaturated, whatever the
  compensator (integrators and unstable compensators included).
- **from rest, driven by references** (sharper, covers less): the closed-loop rounding plus the WCPG of the
  difference between the design's closed loop and the quantised one driven by the same references within their
  ranges from rest at the operating point (open loop: by samples within theirs), the rounded operating point as
  constant offsets.

Every peak gain is of matrices formed in balls (:mod:`gainlink.proof.ball`), through
:func:`~.wcpg.wcpg_ball`: the float64 rounding of forming them is covered.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import DesignError
from ...proof.ball import abs_upper, balls, mid, precise
from ...proof.derived_law import DerivedLaw
from ...synthesis.wcpg import spectral_radius, wcpg_ball
from .formats import Quantised
from .loops import LinearSystem, closed_loop, difference, open_loop
from .ranges import Rounding, centre_half, estimate_columns, estimate_outputs

UP = 1 + 1e-12  # covers the float64 rounding of adding a few non-negative bounds
COEFFICIENTS = ("F", "G", "Ly", "Kx", "Ky", "Kz", "Tr", "Ty")


@dataclass(frozen=True)
class PerStep:
    """One-step bounds against the quantised law (same state before the step): the command ``u`` (m, the float
    the C returns), next ``xh`` (n) and ``z`` (q)."""

    u: np.ndarray
    xh: np.ndarray
    z: np.ndarray


@dataclass(frozen=True)
class Injections:
    """What the coefficients' quantisation injects into each equation of the integer law, written with the
    design's coefficients, for any history in range: ``v`` (m) into the command's sum, ``x`` (n) into the
    estimate's, ``z`` (q) into the integrators'; and the constant offsets and initial-state differences
    (``u_op``, ``y_op``, ``xh0``, ``z0``: quantised minus design, in absolute value)."""

    v: np.ndarray
    x: np.ndarray
    z: np.ndarray
    u_op: np.ndarray
    y_op: np.ndarray
    xh0: np.ndarray
    z0: np.ndarray


def per_step(law: DerivedLaw, h: Rounding) -> PerStep:
    """The resynchronised bounds against the quantised law (module docstring)."""
    dv = np.abs(law.Ky) @ h.y + h.v
    du = dv + h.u + h.c
    xh = np.abs(law.G) @ (dv + h.u) + np.abs(law.Ly) @ h.y + h.x
    kaw = np.abs(law.Kaw) @ dv if law.anti_windup == "backcalc" else 0.0
    z = np.abs(law.Tr) * h.r + np.abs(law.Ty) @ h.y + kaw + h.z
    return PerStep(u=du * UP, xh=xh * UP, z=np.asarray(z) * UP)


@precise
def per_step_design(design: DerivedLaw, ideal: DerivedLaw, rounding: PerStep, inj: Injections) -> np.ndarray:
    """The resynchronised bound of the command against the design's law (module docstring): the quantised law's
    bound, the coefficient term of the command's sum, and the limits' rounding (the clamp moves a command by at
    most how far its limit moved)."""
    limits = np.maximum(_gap(ideal.lo, design.lo), _gap(ideal.hi, design.hi))
    offsets = abs_upper(design.Ky) @ inj.y_op + inj.u_op
    return (rounding.u + inj.v + offsets + limits) * UP


def _gap(x, y) -> np.ndarray:
    """``|x - y|`` rounded up (exact differences of float64 numbers)."""
    return abs_upper(balls(x) - balls(y))


def _errors(design: DerivedLaw, ideal: DerivedLaw) -> dict[str, np.ndarray]:
    """The quantised coefficients minus the design's (balls)."""
    return {k: balls(getattr(ideal, k)) - getattr(design, k) for k in COEFFICIENTS}


def _carried(qz: Quantised, d: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``(C, D)`` over the integer law's estimate recursion (:func:`~.ranges.estimate_columns`) of what the
    coefficient errors carry into the estimate's sum (``dF xh + dG du + dLy dy``, n rows) and the command's
    (``dKx xh + dKy dy``, m rows)."""
    ideal = qz.gains.ideal
    X = np.vstack([d["F"], d["Kx"]])
    U = np.vstack([d["G"], np.zeros((ideal.m, ideal.m))])
    Y = np.vstack([d["Ly"], d["Ky"]])
    return estimate_outputs(ideal, qz.ranges, X, U, Y)


@precise
def coefficient_injections(design: DerivedLaw, qz: Quantised) -> Injections:
    """Bounds of the coefficients' injections (module docstring), ``design`` in balls (``derive(a, exact=True)``):
    each a peak over any history in range.

    Raises
    ------
    DesignError
        The estimate's recursion has no certified peak gain (not reached: the range bounds took it already).
    """
    ideal, ranges = qz.gains.ideal, qz.ranges
    d = _errors(design, ideal)
    C, D = _carried(qz, d)
    B = estimate_columns(ideal, ranges, qz.rounding)
    what = "the coefficient error the estimate carries (the observer's error dynamics F)"
    total = wcpg_ball(ideal.F, B, C, D, what=what).total
    n = ideal.n
    return Injections(
        v=(total[n:] + abs_upper(d["Kz"]) @ qz.bounds.z) * UP,
        x=total[:n],
        z=_integrator_injection(d["Tr"], d["Ty"], ranges),
        u_op=_gap(ideal.u_op, design.u_op),
        y_op=_gap(ideal.y_op, design.y_op),
        xh0=_gap(ideal.xh0, design.xh0),
        z0=_gap(ideal.z0, design.z0),
    )


def _integrator_injection(dTr: np.ndarray, dTy: np.ndarray, ranges) -> np.ndarray:
    """``max |dTr r + dTy y|`` over the ranges: ``|dTr c_r + dTy c_y| + |dTr| h_r + |dTy| h_y`` (exact for a
    box: centres ``c``, half-widths ``h``)."""
    if dTr.size == 0:
        return np.zeros(0)
    (cr, hr), (cy, hy) = centre_half(ranges.r), centre_half(ranges.y)
    spread = abs_upper(dTr) * abs_upper(hr) + abs_upper(dTy) @ abs_upper(hy)
    return (abs_upper(dTr * cr + dTy @ cy) + spread) * UP


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
    """The closed-loop bound against the quantised law (module docstring)."""
    system = closed_loop(law, plant)
    return _bound(system, _rounding_weights(h, loop=True), "the closed loop with the quantised coefficients")


@dataclass(frozen=True)
class InOperation:
    """The headline's bound per input (``total``) and its two parts: the roundings, and the coefficients'
    injections with the offsets and the initial state's quantisation."""

    total: np.ndarray
    rounding: np.ndarray
    coefficients: np.ndarray


@precise
def in_operation_bound(design: DerivedLaw, plant: tuple, qz: Quantised, inj: Injections) -> InOperation:
    """The headline (module docstring): the design's closed loop driven by the roundings and the injections.

    The coefficient part is one system, the integer law's estimate recursion in cascade with the design's closed
    loop (what ``dF xh + dG du + dLy dy`` and ``dKx xh + dKy dy`` carry from the first into the second), driven by
    the estimate's own inputs within their ranges: its peak gain is at most the product of the two (0.55-0.65 of it
    on the examples). The rest of each injection (``|dKz|`` times the integrator's bound, the integrators' own
    ``dTr r + dTy y``, the offsets, the initial state's quantisation) drives the loop as bounded signals.

    Raises
    ------
    DesignError
        The design's closed loop has no certified peak gain.
    """
    h, ideal = qz.rounding, qz.gains.ideal
    loop = closed_loop(design, plant)
    d = _errors(design, ideal)
    signals = {
        "nop": inj.y_op,
        "rv": abs_upper(d["Kz"]) @ qz.bounds.z * UP,
        "rz": (inj.z + inj.z0) * UP,
        "rx": inj.xh0,
        "d": inj.u_op,
    }
    A, B_est, C, D_est = _cascade(loop, qz, d)
    B_sig, D_sig = loop.columns(signals)
    B_h, D_h = loop.columns(_rounding_weights(h, loop=True))
    n = ideal.n
    B = np.hstack([B_est, _below(n, B_sig), _below(n, B_h)])
    D = np.hstack([D_est, D_sig, D_h])
    peak = wcpg_ball(A, B, C, D, what="the design's closed loop (the headline bound)")
    first = B.shape[1] - B_h.shape[1]  # the roundings' columns come last
    rounding = peak.upper[:, first:].sum(axis=1) * UP
    coefficients = (peak.upper[:, :first].sum(axis=1) + peak.formed) * UP
    return InOperation(total=peak.total, rounding=rounding, coefficients=coefficients)


def _cascade(loop: LinearSystem, qz: Quantised, d: dict[str, np.ndarray]) -> tuple[np.ndarray, ...]:
    """``(A, B, C, D)`` of the integer law's estimate recursion (state first, its inputs the columns) in cascade
    with the design's closed loop ``loop``, into which it carries ``dF xh + dG du + dLy dy`` (as ``rx``) and
    ``dKx xh + dKy dy`` (as ``rv``)."""
    ideal = qz.gains.ideal
    n = ideal.n
    C_in, D_in = _carried(qz, d)
    into = loop.B["rx"] @ C_in[:n] + loop.B["rv"] @ C_in[n:]
    A = np.block([[balls(ideal.F), np.zeros((n, loop.A.shape[0]))], [into, loop.A]])
    B = np.vstack([estimate_columns(ideal, qz.ranges, qz.rounding), loop.B["rx"] @ D_in[:n] + loop.B["rv"] @ D_in[n:]])
    C = np.hstack([loop.D["rv"] @ C_in[n:], loop.C])
    return A, B, C, loop.D["rv"] @ D_in[n:]


def _below(n: int, B: np.ndarray) -> np.ndarray:
    """Columns ``B`` of the closed loop as columns of the cascade (nothing into the estimate recursion)."""
    return np.vstack([np.zeros((n, B.shape[1])), B])


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


def _with_centre(system: LinearSystem, name: str, centre: np.ndarray) -> LinearSystem:
    """``system`` with one more input column, ``name_centre``: the constant ``centre`` of input ``name``."""
    B = dict(system.B, **{f"{name}_centre": system.B[name] @ centre[:, None]})
    D = dict(system.D, **{f"{name}_centre": system.D[name] @ centre[:, None]})
    return LinearSystem(A=system.A, B=B, C=system.C, D=D)
