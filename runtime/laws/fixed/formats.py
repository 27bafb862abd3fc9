"""Choosing the fixed-point law's formats: from the declared ranges for the samples and commands, from the
certified range bounds for the states, and growing until the bounds of the quantised law (rounding included)
fit — a variable gets one more integer bit when its own rounding could push it past its range — and no
accumulator can overflow."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ...errors import DesignError
from ...proof.derived_law import DerivedLaw
from ...synthesis.wcpg import spectral_radius
from .gains import (
    FixedGains,
    SignalFormats,
    command_integers,
    deviation_fits,
    finest_accumulator_fracs,
    quantise_law,
)
from .qformat import WORDS, Format, format_for, quantise, real
from .ranges import InputRanges, RangeBounds, Rounding, range_bounds

ACC_LIMIT = 2.0**62  # the integer model's guard: partial sums stay below it
MAX_ROUNDS = 8


@dataclass(frozen=True)
class Quantised:
    """The chosen formats' law: its integers, the rounding half-units, input ranges and verified range bounds."""

    gains: FixedGains
    rounding: Rounding
    ranges: InputRanges
    bounds: RangeBounds
    acc_bounds: dict[str, np.ndarray]  # worst partial sum of each accumulator, integer units


def _interval_format(lo: float, hi: float, op: float, word: int) -> Format:
    """A sample's format: holds the range, the operating point and the deviation from it, after rounding."""
    fmt = format_for(max(abs(lo), abs(hi), hi - op, op - lo), word)
    while True:
        q_lo, q_hi, q_op = (int(quantise(x, fmt.frac)) for x in (lo, hi, op))
        if max(abs(q_lo), abs(q_hi), q_hi - q_op, q_op - q_lo) <= fmt.max_int:
            return fmt
        fmt = Format(word, fmt.frac - 1)


def input_formats(law: DerivedLaw, numeric: str) -> dict[str, tuple[Format, ...]]:
    """Formats of the samples ``y``, references ``r`` (from their ranges) and commands ``u`` (from the limits)."""
    words = WORDS[numeric]
    y = tuple(_interval_format(lo, hi, op, words["sample"]) for lo, hi, op in zip(law.y_min, law.y_max, law.y_op))
    r = ()
    if law.q:
        r_op = -law.Ty @ law.y_op / law.Tr
        r = tuple(_interval_format(lo, hi, op, words["sample"]) for lo, hi, op in zip(law.r_min, law.r_max, r_op))
    u = tuple(_interval_format(lo, hi, op, words["command"]) for lo, hi, op in zip(law.lo, law.hi, law.u_op))
    return {"y": y, "r": r, "u": u}


def quantised_inputs(g: FixedGains) -> InputRanges:
    """The integer law's input intervals in real units (quantised ranges, operating point and limits)."""
    fm, law = g.formats, g.ideal
    fy, fr, fu = fm.frac("y"), fm.frac("r"), fm.frac("u")
    y = (real(quantise(law.y_min, fy), fy), real(quantise(law.y_max, fy), fy))
    r = (real(quantise(law.r_min, fr), fr), real(quantise(law.r_max, fr), fr)) if law.q else (np.zeros(0),) * 2
    du = (real(g.LO_U - g.UOP_U, fu), real(g.HI_U - g.UOP_U, fu))
    return InputRanges(dy=(y[0] - law.y_op, y[1] - law.y_op), y=y, r=r, du=du)


def rounding(g: FixedGains) -> Rounding:
    """Half a unit of each rounding point's format (0 where the shift is exact)."""
    fm = g.formats

    def half(frac, shift=None):
        h = np.ldexp(0.5, -np.asarray(frac, dtype=np.int64))
        return h if shift is None else np.where(shift > 0, h, 0.0)

    return Rounding(
        y=half(fm.frac("y")),
        r=half(fm.frac("r")),
        v=half(fm.frac("v"), g.shift_v),
        u=half(fm.frac("u"), g.shift_u),
        z=half(fm.frac("z"), g.shift_z),
        x=half(fm.frac("xh"), g.shift_x),
        c=command_float_error(g),
    )


def command_float_error(g: FixedGains) -> np.ndarray:
    """Per input, a bound of ``|(float)U 2^-f_u - U 2^-f_u|`` over the command words ``LO_U..HI_U`` (the C
    returns ``(float)U`` times the power of two ``2^-f_u``, exactly): 0 when every such word is a float32
    (``|U| <= 2^24``), else half the float32 spacing at the largest, ``2^(e - 24)`` units for ``2^e <= |U| <
    2^(e+1)``; plus half the least subnormal where a product could be one (``f_u > 126``)."""
    top = np.maximum(np.abs(g.LO_U), np.abs(g.HI_U)).astype(np.int64)
    e = np.array([int(t).bit_length() - 1 for t in top], dtype=np.int64)
    frac = g.formats.frac("u")
    units = np.where(top > 1 << 24, np.ldexp(1.0, np.maximum(e - 24, 0)), 0.0)
    return np.ldexp(units, -frac) + np.where(frac > 126, np.ldexp(1.0, -150), 0.0)


def _real_inputs(law: DerivedLaw) -> InputRanges:
    return InputRanges(
        dy=(law.y_min - law.y_op, law.y_max - law.y_op),
        y=(law.y_min, law.y_max),
        r=(law.r_min, law.r_max) if law.q else (np.zeros(0), np.zeros(0)),
        du=(law.lo - law.u_op, law.hi - law.u_op),
    )


def _state_formats(bounds: RangeBounds, law: DerivedLaw, word: int = 32) -> dict[str, tuple[Format, ...]]:
    v = np.maximum.reduce([bounds.v, bounds.w, np.abs(law.lo), np.abs(law.hi)])
    return {
        "xh": tuple(format_for(b, word) for b in bounds.xh),
        "z": tuple(format_for(b, word) for b in bounds.z),
        "v": tuple(format_for(b, word) for b in v),
    }


def choose(design: DerivedLaw, numeric: str) -> Quantised:
    """Formats and integers for ``design`` (a law with its ranges), verified: every bound fits, no accumulator
    can overflow.

    Raises
    ------
    DesignError
        ``F`` is unstable, the integrator cannot be bounded, or the formats do not settle.
    """
    zero = Rounding(*(np.zeros(k) for k in (design.p, design.q, design.m, design.m, design.q, design.n, design.m)))
    estimate = range_bounds(design, _real_inputs(design), zero)
    fm = SignalFormats(numeric, **input_formats(design, numeric), **_state_formats(estimate, design))
    caps: dict[str, np.ndarray] = {}
    for _ in range(MAX_ROUNDS):
        fm = _fit_command_deviation(design, fm)
        acc = finest_accumulator_fracs(design, fm)
        acc = {k: np.minimum(v, caps[k]) if k in caps else v for k, v in acc.items()}
        g = quantise_law(design, fm, acc)
        _check_quantised_estimate(g.ideal, numeric)
        h, inputs = rounding(g), quantised_inputs(g)
        bounds = range_bounds(g.ideal, inputs, h)
        grown = _grow(fm, _state_formats(bounds, g.ideal))
        acc_bounds = _accumulator_bounds(g, bounds, inputs)
        new_caps = {k: acc[k] - _excess_bits(acc_bounds[k]) for k in acc}
        if grown == fm and all(np.array_equal(new_caps[k], acc[k]) for k in acc):
            return Quantised(gains=g, rounding=h, ranges=inputs, bounds=bounds, acc_bounds=acc_bounds)
        fm, caps = grown, new_caps
    raise DesignError(f"the {numeric} formats did not settle in {MAX_ROUNDS} rounds (bounds keep growing)")


def _fit_command_deviation(law: DerivedLaw, fm: SignalFormats) -> SignalFormats:
    """``fm`` with each command format coarsened until every command's deviation from ``u_op`` fits the command
    word as the integers hold them: ``u_op`` and the limits are rounded in the coarser of the command's two
    formats, which can move ``u_op`` by up to half a unit of that format (a ``u_op`` at a limit then leaves
    ``HI_U - UOP_U`` one past the word). Ends at the latest when the command's format is the coarser one, where
    :func:`_interval_format` made it fit."""
    while True:
        fits = deviation_fits(command_integers(law, fm), fm)
        if fits.all():
            return fm
        u = tuple(f if ok else Format(f.word, f.frac - 1) for f, ok in zip(fm.u, fits))
        fm = replace(fm, u=u)


def _check_quantised_estimate(law: DerivedLaw, numeric: str) -> None:
    radius = spectral_radius(law.F)
    if not radius < 1.0:
        raise DesignError(
            f"with the {numeric} coefficients the estimate's recursion F is unstable (spectral radius {radius:.6g} >= "
            "1), so no format can bound it: " + ('use numeric = "q31"' if numeric == "q15" else "slow the observer")
        )


def _grow(fm: SignalFormats, needed: dict[str, tuple[Format, ...]]) -> SignalFormats:
    """``fm`` with every state format widened (never narrowed) to what ``needed`` asks."""
    changes = {k: tuple(f if f.frac <= g.frac else g for f, g in zip(getattr(fm, k), needed[k])) for k in needed}
    return replace(fm, **changes)


def _excess_bits(bounds: np.ndarray) -> np.ndarray:
    """How many bits each accumulator must give up to stay below :data:`ACC_LIMIT`."""
    return np.array([max(0, math.ceil(math.log2(b / ACC_LIMIT)) + 1) if b >= ACC_LIMIT else 0 for b in bounds])


def _accumulator_bounds(g: FixedGains, b: RangeBounds, inputs: InputRanges) -> dict[str, np.ndarray]:
    """The largest partial sum of each accumulator in integer units (every term at its bound, plus the rounding
    constant), from the signals' integer bounds."""
    fm = g.formats

    def ints(values, frac):
        return np.ceil(np.ldexp(np.asarray(values, dtype=float), np.asarray(frac, dtype=np.int64)))

    XH, Z, W = ints(b.xh, fm.frac("xh")), ints(b.z, fm.frac("z")), ints(b.w, fm.frac("v"))
    dY = ints(np.maximum(np.abs(inputs.dy[0]), np.abs(inputs.dy[1])), fm.frac("y"))
    Y = ints(np.maximum(np.abs(inputs.y[0]), np.abs(inputs.y[1])), fm.frac("y"))
    R = ints(np.maximum(np.abs(inputs.r[0]), np.abs(inputs.r[1])), fm.frac("r"))
    dU = ints(np.maximum(np.abs(inputs.du[0]), np.abs(inputs.du[1])), fm.frac("u"))

    def total(terms, shift):
        acc = np.ldexp(1.0, np.maximum(np.asarray(shift, dtype=np.int64) - 1, 0))
        for block, S in terms:
            acc = acc + block.magnitude(S)
        return acc * (1 + 1e-12)

    return {
        "v": total([(g.KX, XH), (g.KY, dY), (g.KZ, Z)], g.shift_v),
        "z": total([(g.TR, R), (g.TY, Y), (g.KAW, W)], g.shift_z),
        "x": total([(g.F, XH), (g.G, dU), (g.LY, dY)], g.shift_x),
    }
