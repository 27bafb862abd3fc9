"""The linear systems the fixed-point certificate takes peak gains of: the law around the design model with its
rounding points as inputs, and the law on its own (open loop) likewise.

Both are the unsaturated law of :class:`~gainlink.proof.derived_law.DerivedLaw` (no input saturates, no sample
is clipped), in deviations from the operating point, with exogenous inputs named by what they model:

- ``r``: the reference's deviation from the trim ``Ci y_op``;
- ``ny``: an error on the sample the law reads (its quantisation), seen by the estimate and the integrator;
- ``nop``: an offset of the law's ``y_op`` (seen by ``dy`` only);
- ``nr``: an error on the reference (its quantisation);
- ``rv``, ``ru``, ``rz``, ``rx``: the rounding of ``v``, ``u``, ``z``, ``xh``;
- ``d``: an offset at the plant input (the law's ``u_op`` against the plant's).

The closed loop's plant is the design model ``x+ = Ad x + Bd du``, ``y = Cd x + Dd du_prev`` (the feed-through
acts on the previous command, as :class:`~gainlink.proof.sampled_plant.SampledPlant`). Each system is returned as
``(A, B, C, D)`` with ``B`` and ``D`` split into named column blocks, formed in balls
(:mod:`gainlink.proof.ball`: each entry contains the exact value of the products and sums of the law's and the
plant's numbers), so that a peak gain taken of it (:func:`~.wcpg.wcpg_ball`) covers the float64 rounding of
forming it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...proof.ball import balls, precise
from ...proof.derived_law import DerivedLaw

INPUTS = ("r", "ny", "nop", "nr", "rv", "ru", "rz", "rx", "d")


@dataclass(frozen=True)
class LinearSystem:
    """``s+ = A s + sum B[name] w_name``, ``out = C s + sum D[name] w_name``."""

    A: np.ndarray
    B: dict[str, np.ndarray]
    C: np.ndarray
    D: dict[str, np.ndarray]

    def columns(self, weights: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """``(B, D)`` of the named inputs, each column scaled by its weight (the input's bound, a float or a
        ball)."""
        names = [k for k in weights if weights[k].size]
        B = np.hstack([self.B[k] * weights[k][None, :] for k in names]) if names else np.zeros((self.A.shape[0], 0))
        D = np.hstack([self.D[k] * weights[k][None, :] for k in names]) if names else np.zeros((self.C.shape[0], 0))
        return B, D


def _law_balls(law: DerivedLaw) -> DerivedLaw:
    """``law`` with the coefficients the loops use as balls (exact), so that products formed from them are too."""
    names = ("F", "G", "Ly", "Kx", "Ky", "Kz", "Tr", "Ty")
    return replace(law, **{k: balls(getattr(law, k)) for k in names})


class _Affine:
    """Signals as linear maps of the stacked vector ``[s; w]`` (named blocks), to write the loop equation by
    equation."""

    def __init__(self, sizes: dict[str, int]) -> None:
        self.sizes = sizes
        self.offset = {}
        pos = 0
        for k, size in sizes.items():
            self.offset[k] = pos
            pos += size
        self.width = pos

    def of(self, name: str) -> np.ndarray:
        M = np.zeros((self.sizes[name], self.width))
        M[:, self.offset[name] : self.offset[name] + self.sizes[name]] = np.eye(self.sizes[name])
        return M

    def split(self, M: np.ndarray, state: tuple[str, ...]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        A = np.hstack([M[:, self.offset[k] : self.offset[k] + self.sizes[k]] for k in state])
        blocks = {k: M[:, self.offset[k] : self.offset[k] + self.sizes[k]] for k in INPUTS if k in self.sizes}
        return A, blocks


@precise
def closed_loop(law: DerivedLaw, plant: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> LinearSystem:
    """The unsaturated law around the design model; output: the plant's command deviation ``du + d``."""
    feed = bool(np.any(np.asarray(plant[3]) != 0))
    Ad, Bd, Cd, Dd = (balls(M) for M in plant)
    law = _law_balls(law)
    n, m, p, q = law.n, law.m, law.p, law.q
    state = ("x", "xh", "z") + (("dup",) if feed else ())
    sizes = {"x": Ad.shape[0], "xh": n, "z": q, "dup": m if feed else 0}
    sizes |= {"r": q, "ny": p, "nop": p, "nr": q, "rv": m, "ru": m, "rz": q, "rx": n, "d": m}
    s = _Affine(sizes)
    y_dev = Cd @ s.of("x") + (Dd @ s.of("dup") if feed else 0) + s.of("ny")
    dy = y_dev + s.of("nop")
    v = law.Kx @ s.of("xh") + law.Ky @ dy + law.Kz @ s.of("z") + s.of("rv")
    du = v + s.of("ru")
    du_plant = du + s.of("d")
    rows = {
        "x": Ad @ s.of("x") + Bd @ du_plant,
        "xh": law.F @ s.of("xh") + law.G @ du + law.Ly @ dy + s.of("rx"),
        "z": s.of("z") + law.Tr[:, None] * (s.of("r") + s.of("nr")) + law.Ty @ y_dev + s.of("rz"),
        "dup": du_plant,
    }
    A, B = s.split(np.vstack([rows[k] for k in state]), state)
    C, D = s.split(du_plant, state)
    return LinearSystem(A=A, B=B, C=C, D=D)


@precise
def open_loop(law: DerivedLaw) -> LinearSystem:
    """The unsaturated law on its own (no integrators, ``q = 0``), from what it reads to its command deviation.

    Input ``ny`` is whatever is added to the sample deviation ``dy``: its quantisation error for a rounding
    analysis, the sample itself for the coefficient term (both enter alike)."""
    law = _law_balls(law)
    n, m, p = law.n, law.m, law.p
    sizes = {"xh": n, "ny": p, "nop": p, "rv": m, "ru": m, "rx": n, "d": m}
    s = _Affine(sizes)
    dy = s.of("ny") + s.of("nop")
    du = law.Kx @ s.of("xh") + law.Ky @ dy + s.of("rv") + s.of("ru")
    A, B = s.split(law.F @ s.of("xh") + law.G @ du + law.Ly @ dy + s.of("rx"), ("xh",))
    C, D = s.split(du + s.of("d"), ("xh",))
    return LinearSystem(A=A, B=B, C=C, D=D)


def difference(first: LinearSystem, second: LinearSystem, shared: tuple[str, ...]) -> LinearSystem:
    """``second - first`` driven by the same ``shared`` inputs (the others only enter ``second``)."""
    n1, n2 = first.A.shape[0], second.A.shape[0]
    A = np.block([[first.A, np.zeros((n1, n2))], [np.zeros((n2, n1)), second.A]])
    B, D = {}, {}
    for k, B2 in second.B.items():
        B1 = first.B[k] if k in shared else np.zeros((n1, B2.shape[1]))
        B[k] = np.vstack([B1, B2])
        D[k] = second.D[k] - (first.D[k] if k in shared else 0.0)
    return LinearSystem(A=A, B=B, C=np.hstack([-first.C, second.C]), D=D)
