"""Closed-loop simulation of a law against the artifact's own discrete plant, to produce measurement records.

The recorded ``y``, ``r`` (and a scheduled law's external signals ``s``) are exactly what the loop saw, so
replaying them through any engine must reproduce the recorded commands: a quick end-to-end check and the demo's
input data. :func:`closed_loop` is the loop, written once against a law's step (``step(y, r, s)``: any law's
float64 reference, :mod:`gainlink.laws`); :func:`simulate_linear` is the positional law around its one sampled
plant (``gainlink.laws``' ``simulate`` for the scheduled law closes the same loop around its points' model).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DataError
from ..shipping.artifact import Artifact
from .reference import ReferenceLoop
from .sampled_plant import SampledPlant


@dataclass(frozen=True)
class Simulation:
    """Time, plant state, measurements, references, external scheduling signals and commands of a closed-loop
    run."""

    t: np.ndarray  # (N,)
    x: np.ndarray  # (N, n) plant state at each sample (the model's: a deviation from the operating point, or a
    # scheduled law's points' model in absolute coordinates)
    y: np.ndarray  # (N, p)
    r: np.ndarray  # (N, q)
    u: np.ndarray  # (N, m)
    s: np.ndarray | None = None  # (N, e) a scheduled law's external signals (None: the law has none)


class _Positional:
    """The positional law's ``step(y, r)`` as a law's ``step(y, r, s)`` (``s`` unused)."""

    def __init__(self, loop: Any) -> None:
        self.loop = loop

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Any:
        return self.loop.step(y, r)


def closed_loop(
    controller: Any,
    model: Any,
    *,
    Ts: float,
    m: int,
    R: np.ndarray,
    noise: np.ndarray,
    S: np.ndarray,
    before: Callable[[np.ndarray], None] | None = None,
    after: Callable[[], None] | None = None,
) -> Simulation:
    """Close ``controller`` (``step(y, r, s)`` with ``.u``, ``m`` commands) around ``model`` (``outputs()``,
    ``advance(u)``, its state ``x``) for one sample per row of ``R`` (references), ``noise`` (added to the outputs)
    and ``S`` (external scheduling signals); ``before(s)`` hears each sample's signals before the model is sampled,
    ``after()`` runs after each advance (a model that follows its own scheduled output)."""
    steps = R.shape[0]
    T, Y, U = np.arange(steps) * Ts, np.empty((steps, noise.shape[1])), np.empty((steps, m))
    X: list[np.ndarray] = []
    for k in range(steps):
        if before is not None:
            before(S[k])
        y = model.outputs() + noise[k]
        u = np.asarray(controller.step(y, R[k], S[k]).u, dtype=float)
        X.append(np.array(model.x, dtype=float))
        Y[k], U[k] = y, u
        model.advance(u)
        if after is not None:
            after()
    return Simulation(t=T, x=np.array(X).reshape(steps, -1), y=Y, r=np.array(R, dtype=float), u=U,
                      s=np.array(S, dtype=float) if S.shape[1] else None)  # fmt: skip


def simulate_linear(
    artifact: Artifact,
    *,
    steps: int,
    x0: np.ndarray | None = None,
    reference: np.ndarray | None = None,
    noise_std: float = 0.0,
    seed: int = 0,
) -> Simulation:
    """Run the reference loop against the artifact's plant about its operating point.

    The model is in deviations, ``x+ = Ad x + Bd (u - u_op)``; the recorded ``y = y_op + Cd x +
    Dd (u - u_op) + noise`` and ``u`` are absolute, as a sensor and an actuator see them (the same
    as ``x+ = Ad x + Bd u``, ``y = Cd x + Dd u`` when the artifact has no operating point).

    Parameters
    ----------
    artifact : Artifact
        The design; its own discrete plant is simulated.
    steps : int
        Number of samples.
    x0 : array, optional
        Initial plant state, as a deviation from the operating point (zeros by default).
    reference : array, optional
        Constant absolute reference for the tracked outputs (q values; by default the tracked
        outputs' values at the operating point, ``Ci y_op``).
    noise_std : float
        Standard deviation of white measurement noise.
    seed : int
        Seed of the noise generator.
    """
    a = artifact
    if steps < 1:
        raise DataError("steps must be at least 1")
    r = a.r_op if reference is None else np.asarray(reference, float).reshape(a.q)
    plant = SampledPlant.from_artifact(a, x0=x0)  # x0 is a plant state in the design's coordinates
    noise = noise_std * np.random.default_rng(seed).standard_normal((steps, a.p))
    return closed_loop(_Positional(ReferenceLoop(a)), plant, Ts=a.Ts, m=a.m, R=np.tile(r, (steps, 1)), noise=noise,
                       S=np.zeros((steps, 0)))  # fmt: skip


def samples_csv(sim: Simulation) -> str:
    """The measurements of a simulation as a replay input CSV (t, y0.., r0.., and a scheduled law's s0..)."""
    p, q = sim.y.shape[1], sim.r.shape[1]
    S = np.zeros((sim.t.size, 0)) if sim.s is None else sim.s
    head = ["t"] + [f"y{i}" for i in range(p)] + [f"r{i}" for i in range(q)] + [f"s{i}" for i in range(S.shape[1])]
    lines = [",".join(head)]
    for k in range(sim.t.size):
        lines.append(",".join(repr(float(v)) for v in [sim.t[k], *sim.y[k], *sim.r[k], *S[k]]))
    return "\n".join(lines) + "\n"
