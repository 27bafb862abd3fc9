"""Small input steps from a point, on a plant and on a linear model: the experiment behind the interface check
(:mod:`.fmu_check`) and the fit of a linearisation (:mod:`.model_fit`).

The plan comes from a linear model of the plant there. **Horizon**: long enough to see the slowest stable mode
settle (``4 / |Re λ|``) and three periods of a lightly damped one, but no longer than an unstable mode takes to
grow by ``e²`` (``2 / Re λ``), 20 to 2000 steps (200 when the model has no time scale of its own, e.g. a pure
integrator chain). **Amplitude**: per input, the step that moves the most-moved output by :data:`LEVEL` (1 %) of
its scale (``|y|`` at the point, or 1 where that is zero) at its peak over the horizon: small enough to stay
near the point, large enough to stand well above an integrator's tolerance.

A plant runs once with the inputs held at the point (the free response: zero at an equilibrium) and once per
input with that input stepped; the step's response is the difference, so a start that is not at rest (an FMU
whose states at the point cannot be set) does not count as model error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Plant

LEVEL = 0.01
MIN_STEPS, MAX_STEPS, DEFAULT_STEPS = 20, 2000, 200


@dataclass(frozen=True)
class StepPlan:
    """``amplitudes`` (m) added one input at a time to ``u0`` (m) for ``steps`` samples of ``Ts``."""

    u0: np.ndarray
    amplitudes: np.ndarray
    steps: int
    Ts: float


@dataclass(frozen=True)
class StepRuns:
    """A plant's free response ``free`` (K, p) and its step responses ``steps`` (m, K, p), forced minus free:
    the outputs after each held sample."""

    free: np.ndarray
    steps: np.ndarray


def discretise(A: np.ndarray, B: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold ``Ad, Bd`` of a continuous ``A, B`` at ``Ts`` (the matrix exponential)."""
    from scipy.linalg import expm  # here: a HIL run imports this module but checks its FMU only when not cached

    n, m = B.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = A, B
    e = expm(big * Ts)
    return e[:n, :n], e[:n, n:]


def horizon(Ad: np.ndarray, Ts: float) -> int:
    """Samples to record (see the module docstring), from the discrete poles ``z = exp(λ Ts)``."""
    z = np.linalg.eigvals(Ad) if Ad.size else np.zeros(0)
    lam = np.log(z.astype(complex)[np.abs(z) > 0]) / Ts
    tol = 1e-9 / Ts
    grow = lam.real[lam.real > tol]
    if grow.size:
        T = 2.0 / grow.max()
    else:
        decay = -lam.real[lam.real < -tol]
        osc = np.abs(lam.imag[np.abs(lam.imag) > tol])
        spans = [4.0 / decay.min()] if decay.size else []
        spans += [3.0 * 2.0 * np.pi / osc.min()] if osc.size else []
        if not spans:
            return DEFAULT_STEPS
        T = max(spans)
    return int(np.clip(round(T / Ts), MIN_STEPS, MAX_STEPS))


def model_steps(
    Ad: np.ndarray, Bd: np.ndarray, Cd: np.ndarray, Dd: np.ndarray, *, du: np.ndarray, steps: int
) -> np.ndarray:
    """Responses (m, K, p) of the discrete model from rest to a held step ``du[j]`` on input j alone, sampled as a
    plant is: after each held sample, ``y_k = Cd x_k + Dd u`` (the step is still applied)."""
    n, m = Bd.shape
    out = np.zeros((m, steps, Cd.shape[0]))
    for j in range(m):
        u = np.zeros(m)
        u[j] = du[j]
        x = np.zeros(n)
        for k in range(steps):
            x = Ad @ x + Bd @ u
            out[j, k] = Cd @ x + Dd @ u
    return out


def plan_steps(
    Ad: np.ndarray, Bd: np.ndarray, Cd: np.ndarray, Dd: np.ndarray, *, u0: np.ndarray, y0: np.ndarray, Ts: float
) -> StepPlan:
    """The experiment for a plant whose discrete model at the point is ``Ad, Bd, Cd, Dd`` (see the module)."""
    K = horizon(Ad, Ts)
    m = Bd.shape[1]
    unit = model_steps(Ad, Bd, Cd, Dd, du=np.ones(m), steps=K)  # (m, K, p)
    scale = np.where(np.abs(y0) > 0, np.abs(y0), 1.0)
    peak = (np.abs(unit).max(axis=1) / scale).max(axis=1) if K else np.zeros(m)  # (m,): relative peak per unit
    amplitudes = np.where(peak > 0, LEVEL / np.where(peak > 0, peak, 1.0), LEVEL * np.maximum(np.abs(u0), 1.0))
    return StepPlan(u0=np.asarray(u0, float), amplitudes=amplitudes, steps=K, Ts=float(Ts))


def run_steps(plant: Plant, plan: StepPlan, *, initial: dict, factor: float = 1.0) -> StepRuns:
    """The free response and one step response per input (amplitudes times ``factor``) of ``plant``, each run
    from ``plant.reset(initial=initial)``."""
    free = _held(plant, initial, np.tile(plan.u0, (plan.steps, 1)), plan.Ts)
    m = plan.u0.size
    steps = np.zeros((m, plan.steps, free.shape[1]))
    for j in range(m):
        u = np.tile(plan.u0, (plan.steps, 1))
        u[:, j] += factor * plan.amplitudes[j]
        steps[j] = _held(plant, initial, u, plan.Ts) - free
    return StepRuns(free=free, steps=steps)


def _held(plant: Plant, initial: dict, u: np.ndarray, Ts: float) -> np.ndarray:
    plant.reset(initial=initial)
    out = np.zeros((u.shape[0], len(plant.output_names)))
    for k in range(u.shape[0]):
        plant.advance(u=u[k], dt=Ts)
        out[k] = plant.outputs()
    return out
