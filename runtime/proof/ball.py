"""Matrices of balls (python-flint ``arb``, held in numpy object arrays), for forming a certificate's matrices
without losing track of their rounding.

A certificate takes peak gains of matrices built from products and sums of the artifact's numbers (``Ad - L Cd``,
``Bd Kx``, the closed loop of a law around its plant). Formed in float64 they are off by a rounding that the
peak gain then no longer covers. Formed here instead, every entry is a ball that contains the exact value: the
float64 numbers enter exactly (:func:`balls`), numpy's ``@``, ``+``, ``-`` and slicing work on the object arrays
as on floats (a float or an integer mixed in is converted exactly), and :func:`split` gives the float64 matrix a
peak gain is taken of with a bound on its distance from the exact one (:func:`gainlink.synthesis.wcpg.wcpg_ball`
covers that distance).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import ParamSpec, TypeVar

import numpy as np

PREC = 128  # bits: products of float64 numbers are exact, sums nearly so (the radius holds what is not)
P = ParamSpec("P")
T = TypeVar("T")


@contextmanager
def precision(bits: int = PREC) -> Iterator[None]:
    """Form balls with ``bits`` of precision inside the block (python-flint's context is global)."""
    from flint import ctx

    old, ctx.prec = ctx.prec, bits
    try:
        yield
    finally:
        ctx.prec = old


def precise(fn: Callable[P, T]) -> Callable[P, T]:
    """``fn`` run under :func:`precision` (a function that forms balls: a cancellation keeps its digits)."""

    @functools.wraps(fn)
    def run(*args: P.args, **kwargs: P.kwargs) -> T:
        with precision():
            return fn(*args, **kwargs)

    return run


def balls(M) -> np.ndarray:
    """``M`` (numbers, arrays, or already balls) as an object array of exact balls."""
    from flint import arb

    M = np.asarray(M, dtype=object) if isinstance(M, np.ndarray) and M.dtype == object else np.asarray(M)
    out = np.empty(M.shape, dtype=object)
    for idx, x in np.ndenumerate(M):
        out[idx] = x if isinstance(x, arb) else arb(float(x)) if isinstance(x, float | np.floating) else arb(int(x))
    return out


def is_balls(M) -> bool:
    """True for an object array (of balls)."""
    return isinstance(M, np.ndarray) and M.dtype == object


def upper(x) -> float:
    """A float64 at or above ``|x|`` (``x`` a ball or a number)."""
    from flint import arb

    if not isinstance(x, arb):
        return abs(float(x))
    u = x.abs_upper()
    man, exp = u.man_exp()
    man = int(man)
    value = math.ldexp(float(man), int(exp))
    return float(np.nextafter(value, np.inf)) if man.bit_length() > 53 or not math.isfinite(value) else value


def abs_upper(M) -> np.ndarray:
    """Entrywise float64 upper bounds of ``|M|``."""
    if not is_balls(M):
        return np.abs(np.asarray(M, dtype=np.float64))
    return np.array([upper(x) for x in M.ravel()], dtype=np.float64).reshape(M.shape)


def split(M) -> tuple[np.ndarray, np.ndarray]:
    """``(F, E)``: the float64 matrix nearest ``M``'s midpoints and a bound ``E >= |M - F|`` entrywise (zero where
    ``M`` holds a float64 number exactly)."""
    from flint import arb

    if not is_balls(M):
        F = np.asarray(M, dtype=np.float64)
        return F, np.zeros_like(F)
    F = np.empty(M.shape, dtype=np.float64)
    E = np.zeros(M.shape, dtype=np.float64)
    for idx, x in np.ndenumerate(M):
        if isinstance(x, arb):
            f = float(x.mid())
            F[idx], E[idx] = f, upper(x - arb(f))
        else:
            F[idx] = float(x)
            if F[idx] != x:
                E[idx] = upper(arb(int(x)) - arb(F[idx])) if isinstance(x, int | np.integer) else math.inf
    return F, E


def mid(M) -> np.ndarray:
    """The float64 matrix nearest ``M`` (for estimates, not bounds)."""
    return split(M)[0] if is_balls(M) else np.asarray(M, dtype=np.float64)
