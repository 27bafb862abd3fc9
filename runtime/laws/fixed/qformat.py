"""Binary formats and the integer operations of the fixed-point law, written once for the model and the certificate.

A signal in format ``(word, frac)`` is a two's-complement integer ``X`` of ``word`` bits (sign included) meaning
``X * 2**-frac``; ``frac`` may exceed ``word - 1`` (a small signal) or be negative (a large one). The operations
are those the C performs, on numpy ``int64`` arrays:

- :func:`quantise`: a double to the nearest integer of the format, ties upward (``floor(x * 2**frac + 1/2)``,
  evaluated exactly as ``q = floor(x'); q += (x' - q >= 1/2)`` with ``x' = x * 2**frac``, exact in double);
- :func:`rshift_round`: an accumulator to a coarser format, round half up by add-then-arithmetic-shift,
  ``(acc + 2**(s-1)) >> s`` for ``s > 0``, ``acc`` for ``s == 0``, ``acc * 2**-s`` (exact) for ``s < 0``;
- :func:`saturate`: to the word's range ``[-2**(word-1), 2**(word-1) - 1]``, with a flag when it had to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ACC_BITS = 64

# Word lengths per role (docs/design.md, fixed point): q15 keeps states, integrators, the unsaturated command and
# the accumulators wide (16-bit states would miss 1/4096 of the span and put a dead zone in the integrator).
WORDS = {
    "q31": {"coefficient": 32, "sample": 32, "command": 32, "state": 32},
    "q15": {"coefficient": 16, "sample": 16, "command": 16, "state": 32},
}


@dataclass(frozen=True)
class Format:
    """A binary format: ``word`` bits with the sign, ``frac`` fractional bits (value = integer * 2**-frac)."""

    word: int
    frac: int

    @property
    def max_int(self) -> int:
        """The largest integer of the word."""
        return (1 << (self.word - 1)) - 1

    @property
    def int_bits(self) -> int:
        """Bits left of the binary point (the sign not counted); negative for a format below 1/2."""
        return self.word - 1 - self.frac

    @property
    def lsb(self) -> float:
        """The value of one unit in the last place."""
        return math.ldexp(1.0, -self.frac)

    @property
    def range(self) -> float:
        """The largest value the format holds."""
        return math.ldexp(float(self.max_int), -self.frac)

    def headroom_bits(self, bound: float) -> float:
        """log2 of the format's range over ``bound`` (how many doublings of the bound still fit)."""
        return math.log2(self.range / bound) if bound > 0 else float("inf")

    def to_dict(self) -> dict:
        """JSON form: word, fractional and integer bits, the Q notation."""
        return {"word": self.word, "frac": self.frac, "int_bits": self.int_bits, "q": f"Q{self.int_bits}.{self.frac}"}


def format_for(bound: float, word: int) -> Format:
    """The format of ``word`` bits with the most fractional bits whose range holds ``bound`` (and its rounding)."""
    bound = float(bound)
    if not math.isfinite(bound):
        raise ValueError(f"cannot give a {word}-bit format to an unbounded variable")
    if bound <= 0.0:
        return Format(word, word - 1)
    frac = word - 1 - math.ceil(math.log2(bound))
    while math.floor(math.ldexp(bound, frac) + 0.5) > (1 << (word - 1)) - 1:
        frac -= 1
    while math.floor(math.ldexp(bound, frac + 1) + 0.5) <= (1 << (word - 1)) - 1:
        frac += 1
    return Format(word, frac)


def quantise(x, frac) -> np.ndarray:
    """Round ``x * 2**frac`` to the nearest integer, ties upward, exactly (``frac`` a scalar or per entry)."""
    scaled = np.ldexp(np.asarray(x, dtype=np.float64), np.asarray(frac, dtype=np.int64))
    q = np.floor(scaled)
    return (q + (scaled - q >= 0.5)).astype(np.int64)


def quantise_inward(lo, hi, frac) -> tuple[np.ndarray, np.ndarray]:
    """``lo`` rounded up and ``hi`` rounded down to the format: quantised limits never leave the real ones."""
    lo_s = np.ldexp(np.asarray(lo, dtype=np.float64), np.asarray(frac, dtype=np.int64))
    hi_s = np.ldexp(np.asarray(hi, dtype=np.float64), np.asarray(frac, dtype=np.int64))
    return np.ceil(lo_s).astype(np.int64), np.floor(hi_s).astype(np.int64)


def rshift_round(acc: np.ndarray, shift) -> np.ndarray:
    """``acc`` (int64) to a format ``shift`` bits coarser, round half up: ``(acc + 2**(s-1)) >> s``; a negative
    shift multiplies by ``2**-s`` (exact)."""
    acc = np.asarray(acc, dtype=np.int64)
    s = np.broadcast_to(np.asarray(shift, dtype=np.int64), acc.shape)
    right = np.maximum(s, 0)
    half = np.where(right > 0, np.left_shift(np.int64(1), np.maximum(right - 1, 0)), 0)
    down = np.right_shift(acc + half, right)
    return np.where(s >= 0, down, np.left_shift(acc, np.maximum(-s, 0)))


def saturate(x: np.ndarray, word) -> tuple[np.ndarray, np.ndarray]:
    """``x`` clipped to the two's-complement range of ``word`` bits, and where it had to be."""
    x = np.asarray(x, dtype=np.int64)
    w = np.asarray(word, dtype=np.int64)
    hi = np.left_shift(np.int64(1), w - 1) - 1
    lo = -hi - 1
    return np.minimum(np.maximum(x, lo), hi), (x > hi) | (x < lo)


def real(x: np.ndarray, frac) -> np.ndarray:
    """The value of integers ``x`` in a format with ``frac`` fractional bits."""
    return np.ldexp(np.asarray(x, dtype=np.float64), -np.asarray(frac, dtype=np.int64))
