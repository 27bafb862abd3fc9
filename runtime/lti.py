"""The one container of a linear model: ``A, B, C, D`` with signal names, continuous or sampled.

The plant a spec gives (:class:`gainlink.spec.PlantModel`), the discrete plant a design is made for
(:class:`gainlink.synthesis.discretize.Discretised`), the bridge's linear plant model
(:class:`gainlink.hil.plants.linear.LinearModel`) and a linearised FMU
(:class:`gainlink.hil.plants.linearize.Linearization`) all extend this class with what is theirs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, kw_only=True)
class StateSpaceModel:
    """``x+ = A x + B u`` (sampled at ``Ts``) or ``dx/dt = A x + B u`` (``Ts`` None), ``y = C x + D u``; signal names
    default to ``x0.., u0.., y0..``."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    Ts: float | None = None

    def __post_init__(self) -> None:
        for field, count, prefix in (("states", self.n, "x"), ("inputs", self.m, "u"), ("outputs", self.p, "y")):
            if not getattr(self, field):
                object.__setattr__(self, field, tuple(f"{prefix}{i}" for i in range(count)))

    @property
    def n(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    @property
    def m(self) -> int:
        """Number of inputs."""
        return self.B.shape[1]

    @property
    def p(self) -> int:
        """Number of outputs."""
        return self.C.shape[0]

    @property
    def continuous(self) -> bool:
        """True when the model is continuous-time (no sample time)."""
        return self.Ts is None
