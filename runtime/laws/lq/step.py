"""The C step (``gl_step_core``) as straight-line Python for one artifact: the fast path of
:class:`gainlink.laws.lq.model.Float32Loop`.

As the firmware's export unrolls the step for fixed dimensions (``gl_step.h``), :func:`compile_step` writes the same
operations in the same order as Python source with the coefficients as literals, and compiles it once per loop.
Each operation is rounded to float32 by a store into a one-element ``array("f")``. Each ``fmaf`` is computed as
``a*b`` (exact in float64) plus ``c``, rounded to float64 and then to float32; its operands are also stored, and all
of them are checked at once after the step: unless a float64 sum sits on a float32 rounding midpoint that the exact
sum does not, the double rounding equals one correctly rounded ``fmaf`` for every operation, and the step stands;
otherwise the caller redoes it exactly (:meth:`Float32Loop._core`). A step costs about a third of the term-by-term
interpreter's, and this check runs for every design.
"""

from __future__ import annotations

import functools
import math
from array import array
from collections.abc import Callable

import numpy as np

MID_MASK = np.uint64((1 << 29) - 1)  # float64 significand bits below float32's precision
MID_HALF = np.uint64(1 << 28)  # ... equal to this: the value sits exactly on a float32 midpoint


class _Writer:
    """Emits the step's lines, naming each rounded value and counting the ``fmaf`` sums."""

    def __init__(self, w: list[float]) -> None:
        self.w, self.pos, self.fmas, self.temps = w, 0, 0, 0
        self.lines: list[str] = []

    def coef(self) -> str:
        value = self.w[self.pos]
        self.pos += 1
        return f"({value!r})" if math.isfinite(value) else f"float('{value!r}')"

    def rounded(self, expr: str, name: str | None = None) -> str:
        if name is None:
            name, self.temps = f"t{self.temps}", self.temps + 1
        self.lines += [f"B[0] = {expr}", f"{name} = B[0]"]
        return name

    def fma(self, a: str, b: str, c: str, name: str | None = None) -> str:
        k, self.fmas = self.fmas, self.fmas + 1
        self.lines += [f"P[{k}] = prod = {a} * {b}", f"C[{k}] = c = {c}"]
        return self.rounded("prod + c", name)


def compile_step(w: list[float], *, n: int, m: int, p: int, q: int, current: bool, anti_windup: str) -> Callable:
    """``core(xh, z, ys, rs) -> (u, v, sat, xn, zn, inexact)`` for the coefficient stream ``w`` (the order of
    ``gl_step_core``), every list of Python floats holding float32 values; ``inexact`` is True when the double
    rounding of some ``fmaf`` may differ from its one rounding, and the step must then be redone exactly."""
    wr = _Writer(w)
    _inputs(wr, n=n, p=p, q=q)
    _commands(wr, n=n, m=m, p=p, q=q, current=current)
    _integrators(wr, m=m, p=p, q=q, anti_windup=anti_windup)
    _estimate(wr, n=n, m=m, p=p)
    assert wr.pos == len(w), "the step did not consume the coefficient stream"
    names = lambda prefix, k: "[" + ", ".join(f"{prefix}{i}" for i in range(k)) + "]"  # noqa: E731
    wr.lines.append(
        f"return {names('u', m)}, {names('v', m)}, {names('sat', m)}, {names('xn', n)}, {names('zn', q)}, inexact()"
    )
    source = "def core(xh, z, ys, rs):\n" + "".join(f"    {line}\n" for line in wr.lines)
    prods, addends = array("d", bytes(8 * wr.fmas)), array("d", bytes(8 * wr.fmas))
    scope = {"B": array("f", [0.0]), "P": prods, "C": addends}
    scope["inexact"] = functools.partial(_inexact, np.frombuffer(prods), np.frombuffer(addends))
    exec(compile(source, "<gainlink float32 step>", "exec"), scope)
    return scope["core"]


def _inexact(prod: np.ndarray, c: np.ndarray) -> bool:
    """True when some ``prod + c`` of the step, rounded to float64, sits on a float32 midpoint that the exact sum
    does not: there the two roundings may differ from ``fmaf``'s one."""
    s = prod + c
    tie = (s.view(np.uint64) & MID_MASK) == MID_HALF
    if not tie.any():
        return False
    prod, c, s = prod[tie], c[tie], s[tie]
    bb = s - prod
    err = (prod - (s - bb)) + (c - bb)  # TwoSum: the exact sum is s + err
    return bool(np.any(err != 0.0))


def _unpack(wr: _Writer, prefix: str, source: str, count: int) -> None:
    if count:
        wr.lines.append(", ".join(f"{prefix}{i}" for i in range(count)) + f", = {source}")


def _inputs(wr: _Writer, *, n: int, p: int, q: int) -> None:
    """The states, integrators, samples and references into locals; ``dy = y - y_op``."""
    _unpack(wr, "x", "xh", n)
    _unpack(wr, "z", "z", q)
    _unpack(wr, "y", "ys", p)
    _unpack(wr, "r", "rs", q)
    for k in range(p):
        wr.fma("1.0", f"y{k}", f"-{wr.coef()}", f"dy{k}")


def _commands(wr: _Writer, *, n: int, m: int, p: int, q: int, current: bool) -> None:
    """``v = u_op + dv``, clamped to the limits; ``du = u - u_op``."""
    for i in range(m):
        uop = wr.coef()
        acc = wr.rounded(f"{wr.coef()} * x0")
        for j in range(1, n):
            acc = wr.fma(wr.coef(), f"x{j}", acc)
        for k in range(p if current else 0):
            acc = wr.fma(wr.coef(), f"dy{k}", acc)
        for j in range(q):
            acc = wr.fma(wr.coef(), f"z{j}", acc)
        lo, hi = wr.coef(), wr.coef()
        wr.fma("1.0", uop, acc, f"v{i}")
        wr.lines += [
            f"u{i}, sat{i} = v{i}, False",
            f"if v{i} < {lo}:",
            f"    u{i}, sat{i} = {lo}, True",
            f"elif v{i} > {hi}:",
            f"    u{i}, sat{i} = {hi}, True",
        ]
        wr.fma("1.0", f"u{i}", f"-{uop}", f"du{i}")


def _integrators(wr: _Writer, *, m: int, p: int, q: int, anti_windup: str) -> None:
    """``z += Ts (r - Ci y)`` (plus ``Kaw (u - v)`` for back-calculation; held on saturation for clamp)."""
    for j in range(q):
        e = f"r{j}"
        for k in range(p):
            e = wr.fma(wr.coef(), f"y{k}", e)
        zj = wr.fma(wr.coef(), e, f"z{j}")
        if anti_windup == "backcalc":
            for k in range(m):
                zj = wr.fma(wr.coef(), wr.fma("1.0", f"u{k}", f"-v{k}"), zj)
        wr.lines.append(f"zn{j} = {zj}")
        if anti_windup == "clamp":
            wr.lines.append(f"if {' or '.join(f'sat{k}' for k in range(m))}:")
            wr.lines.append(f"    zn{j} = z{j}")


def _estimate(wr: _Writer, *, n: int, m: int, p: int) -> None:
    """``xh = F xh + G du + Ly dy``."""
    for i in range(n):
        acc = wr.rounded(f"{wr.coef()} * x0")
        for j in range(1, n):
            acc = wr.fma(wr.coef(), f"x{j}", acc)
        for k in range(m):
            acc = wr.fma(wr.coef(), f"du{k}", acc)
        for k in range(p):
            acc = wr.fma(wr.coef(), f"dy{k}", acc)
        wr.lines.append(f"xn{i} = {acc}")
