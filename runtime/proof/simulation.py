"""Closed-loop simulation of the artifact's own discrete plant, to produce measurement records.

The recorded ``y`` and ``r`` are exactly what the loop saw, so replaying them through any engine
must reproduce the recorded commands: a quick end-to-end check and the demo's input data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError
from ..shipping.artifact import Artifact
from .reference import ReferenceLoop
from .sampled_plant import SampledPlant


@dataclass(frozen=True)
class Simulation:
    """Time, plant state, measurements, references and commands of a closed-loop run."""

    t: np.ndarray  # (N,)
    x: np.ndarray  # (N, n) plant state at each sample (deviation from the operating point)
    y: np.ndarray  # (N, p)
    r: np.ndarray  # (N, q)
    u: np.ndarray  # (N, m)


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
    a.require_unscheduled("the closed-loop simulation")
    if steps < 1:
        raise DataError("steps must be at least 1")
    r = a.r_op if reference is None else np.asarray(reference, float).reshape(a.q)
    rng = np.random.default_rng(seed)
    plant = SampledPlant.from_artifact(a, x0=x0)  # x0 is a plant state in the design's coordinates
    loop = ReferenceLoop(a)
    T, X, Y, R, U = (
        np.empty(steps),
        np.empty((steps, a.n)),
        np.empty((steps, a.p)),
        np.empty((steps, a.q)),
        np.empty((steps, a.m)),
    )
    for k in range(steps):
        y = plant.outputs() + noise_std * rng.standard_normal(a.p)
        u = loop.step(y, r).u
        T[k], X[k], Y[k], R[k], U[k] = k * a.Ts, plant.x, y, r, u
        plant.advance(u)
    return Simulation(t=T, x=X, y=Y, r=R, u=U)


def samples_csv(sim: Simulation) -> str:
    """The measurements of a simulation as a replay input CSV (t, y0.., r0..)."""
    p, q = sim.y.shape[1], sim.r.shape[1]
    lines = [",".join(["t"] + [f"y{i}" for i in range(p)] + [f"r{i}" for i in range(q)])]
    for k in range(sim.t.size):
        lines.append(",".join(repr(float(v)) for v in [sim.t[k], *sim.y[k], *sim.r[k]]))
    return "\n".join(lines) + "\n"
