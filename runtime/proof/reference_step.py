"""The float64 law's step (:class:`gainlink.proof.reference.ReferenceLoop`) as straight-line Python for one artifact.

The law's step is a few small matrix-vector products; in numpy each is a call costing about a microsecond whatever
its size, and a step made some twenty-five of them (45-60 us). :func:`compile_reference_step` writes the same
operations, in the order the law states them (docs/design.md, "The control law"), as Python float arithmetic with
the artifact's matrices as literals, compiled once per artifact. Each product is summed left to right over every
term, zeros included (``0 * inf`` is NaN here as in numpy). Only the order of the sums inside a product may differ
from numpy's (whose BLAS kernel picks its own, per machine): the results agree to the last bits of float64.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..shipping.artifact import Artifact


def _lit(value: float) -> str:
    value = float(value)
    return f"({value!r})" if math.isfinite(value) else f"float('{value!r}')"


class _Writer:
    """Lines of the step; ``columns``: each name holds a column of a block's runs (numpy float64 arrays), so the two
    choices of the law are written with ``where`` and ``|``, every arithmetic operation unchanged."""

    def __init__(self, *, columns: bool = False) -> None:
        self.lines: list[str] = []
        self.columns = columns

    def choose(self, cond: str, then: str, other: str) -> str:
        """``then if cond else other``."""
        return f"where({cond}, {then}, {other})" if self.columns else f"{then} if {cond} else {other}"

    def any_of(self, names: list[str]) -> str:
        """True where any of ``names`` is."""
        return (" | ".join(names) if self.columns else " or ".join(names)) or "False"

    def let(self, name: str, expr: str) -> str:
        self.lines.append(f"{name} = {expr}")
        return name

    def vector(self, prefix: str, exprs: list[str]) -> list[str]:
        return [self.let(f"{prefix}{i}", e) for i, e in enumerate(exprs)]


def _dot(row: np.ndarray, names: list[str]) -> str:
    """``row @ names`` summed left to right (``0.0`` for an empty row)."""
    terms = [f"{_lit(c)} * {x}" for c, x in zip(row, names, strict=True)]
    return "(" + " + ".join(terms) + ")" if terms else "0.0"


def _matvec(mat: np.ndarray, names: list[str]) -> list[str]:
    return [_dot(mat[i], names) for i in range(mat.shape[0])]


#: the law's terms: what the compiled step depends on, and so its cache key
_TERMS = ("y_op", "u_op", "u_min", "u_max", "K", "Ki", "M", "Cd", "Ci", "Kaw", "Ad", "Bd", "Dd", "L")


def compile_reference_block(artifact: Artifact) -> Callable:
    """The step of :func:`compile_reference_step` over a block of runs: the same source, operation for operation,
    with each name a column of the runs (``xh`` (n, B), ``z`` (q, B), ``y`` (p, B), ``r`` (q, B) in, lists of (B,)
    columns out) and the law's two choices (a clamp, the held integrator) written with ``numpy.where``. Every
    operation is elementwise IEEE float64, as Python's float arithmetic is, so each run's column equals its own step
    bit for bit (for finite samples; the caller refuses the others)."""
    return _cached(artifact, columns=True)


def compile_reference_step(artifact: Artifact) -> Callable:
    """``step(xh, z, y, r) -> (u, v, saturated, xh_next, z_next)`` on lists of Python floats, for a finite sample
    (the caller refuses the others), as :meth:`ReferenceLoop.step` defines it; compiled once per law in a process,
    keyed by everything the step is written from (the forms, Ts and the bytes of the matrices), so two artifacts share
    a step only when they compute the same law."""
    return _cached(artifact, columns=False)


def _cached(a: Artifact, *, columns: bool) -> Callable:
    key = (columns, a.observer_form, a.anti_windup, a.Ts,
           *((np.shape(getattr(a, t)), _bytes(getattr(a, t))) for t in _TERMS))  # fmt: skip
    step = _CACHE.get(key)
    if step is None:
        if len(_CACHE) >= _CACHE_MAX:
            _CACHE.pop(next(iter(_CACHE)))
        step = _CACHE[key] = _compile(a, columns=columns)
    return step


_CACHE: dict[tuple, Callable] = {}
_CACHE_MAX = 64


def _bytes(value) -> bytes:
    return np.ascontiguousarray(value, dtype=float).tobytes()


def _compile(a: Artifact, *, columns: bool) -> Callable:
    wr = _Writer(columns=columns)
    xh, z = [f"xh[{i}]" for i in range(a.n)], [f"z[{j}]" for j in range(a.q)]
    y, r = [f"y[{k}]" for k in range(a.p)], [f"r[{j}]" for j in range(a.q)]
    dy = wr.vector("dy", [f"{yk} - {_lit(o)}" for yk, o in zip(y, a.y_op, strict=True)])
    if a.observer_form == "current":
        innov = wr.vector("nu", [f"{d} - {c}" for d, c in zip(dy, _matvec(a.Cd, xh), strict=True)])
        xc = wr.vector("xc", [f"{x} + {c}" for x, c in zip(xh, _matvec(a.M, innov), strict=True)])
    else:
        xc = xh
    kx, kz = _matvec(a.K, xc), _matvec(a.Ki, z)
    v = wr.vector("v", [f"{_lit(o)} - {k1} - {k2}" for o, k1, k2 in zip(a.u_op, kx, kz, strict=True)])
    u = []
    for i, vi in enumerate(v):
        wr.let(f"u{i}", wr.choose(f"{vi} < {_lit(a.u_min[i])}", _lit(a.u_min[i]), vi))  # NaN stays NaN, as np.maximum
        u.append(wr.let(f"u{i}", wr.choose(f"u{i} > {_lit(a.u_max[i])}", _lit(a.u_max[i]), f"u{i}")))
    sat = wr.vector("s", [f"{ui} != {vi}" for ui, vi in zip(u, v, strict=True)])
    _integrators(wr, a, z=z, y=y, r=r, u=u, v=v, sat=sat)
    du = wr.vector("du", [f"{ui} - {_lit(o)}" for ui, o in zip(u, a.u_op, strict=True)])
    _estimate(wr, a, xh=xh, xc=xc, dy=dy, du=du)
    lst = lambda names: "[" + ", ".join(names) + "]"  # noqa: E731
    zn = [f"zn{j}" for j in range(a.q)]
    wr.lines.append(f"return {lst(u)}, {lst(v)}, {lst(sat)}, {lst([f'xn{i}' for i in range(a.n)])}, {lst(zn)}")
    source = "def step(xh, z, y, r):\n" + "".join(f"    {line}\n" for line in wr.lines)
    scope: dict = {"where": np.where}
    exec(compile(source, f"<gainlink float64 step {a.name}>", "exec"), scope)
    return scope["step"]


def _integrators(wr: _Writer, a: Artifact, *, z, y, r, u, v, sat) -> None:
    """``e = r - Ci y``; ``z + Ts e``, held while any input saturates (clamp), plus ``Kaw (u - v)`` (backcalc)."""
    e = wr.vector("e", [f"{rj} - {c}" for rj, c in zip(r, _matvec(a.Ci, y), strict=True)])
    grown = [f"{zj} + {_lit(a.Ts)} * {ej}" for zj, ej in zip(z, e, strict=True)]
    if a.anti_windup == "clamp":
        held = wr.any_of(sat)
        grown = [wr.choose(f"({held})", zj, g) for zj, g in zip(z, grown, strict=True)]
    elif a.anti_windup == "backcalc":
        diff = [f"({ui} - {vi})" for ui, vi in zip(u, v, strict=True)]
        grown = [f"{g} + {c}" for g, c in zip(grown, _matvec(a.Kaw, diff), strict=True)]
    wr.vector("zn", grown)


def _estimate(wr: _Writer, a: Artifact, *, xh, xc, dy, du) -> None:
    """Current form ``Ad xc + Bd du``; predictor form ``Ad xh + Bd du + L (dy - Cd xh - Dd du)``."""
    base = [f"{p1} + {p2}" for p1, p2 in zip(_matvec(a.Ad, xc), _matvec(a.Bd, du), strict=True)]
    if a.observer_form != "current":
        cx, dd = _matvec(a.Cd, xh), _matvec(a.Dd, du)
        innov = wr.vector("w", [f"{d} - {c1} - {c2}" for d, c1, c2 in zip(dy, cx, dd, strict=True)])
        base = [f"{b} + {c}" for b, c in zip(base, _matvec(a.L, innov), strict=True)]
    wr.vector("xn", base)
