"""Identify a discrete-time linear model of a Co-Simulation-only FMU at its communication step.

A Co-Simulation FMU gives no derivatives and hides part of its state (a dead time's delay line, an
internal solver's history), so its Jacobians cannot be read off. What it does give, when it can
save and restore its state (``fmi2GetFMUstate`` / ``fmi3GetFMUState``), is the exact response of
``doStep`` to a perturbed input from one and the same state. From the operating point (start
values, inputs held at ``u0``) the response to a pulse ``u0 +- delta e_j`` held over one step is
recorded for ``horizon`` steps, each run restored from the saved state; central differences give
the Markov parameters ``h_k = C A^(k-1) B`` (``k >= 1``) of the sampled system, exact for a linear
FMU up to rounding. The Eigensystem Realization Algorithm (Ho-Kalman: SVD of the block Hankel
matrix of the ``h_k``) turns them into a minimal ``(A, B, C)``; the order is the number of Hankel
singular values above ``rtol`` times the largest. ``D = 0``: the bridge samples the outputs after
each step, before the next command is applied.

The realised states are balanced coordinates (named ``x0, x1, ...``), not the FMU's variables;
the model is equal to the FMU's input/output behaviour at the step, which is what a design needs.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import PlantError

from .fmu import FmuPlant

DEFAULT_HORIZON = 100


def _pulse_responses(plant: FmuPlant, *, u0: np.ndarray, dt: float, horizon: int, rel_step: float) -> np.ndarray:
    """Markov parameters ``h[k-1] = dy_k / du_0`` (p x m) for ``k = 1..horizon``, by central differences."""
    start = plant.save_state()
    m, p = len(u0), len(plant.output_names)
    h = np.zeros((horizon, p, m))
    for j in range(m):
        delta = rel_step * max(1.0, abs(u0[j]))
        runs = []
        for sign in (1.0, -1.0):
            plant.restore_state(start)
            u = u0.copy()
            u[j] += sign * delta
            ys = []
            for k in range(horizon):
                plant.advance(u=u if k == 0 else u0, dt=dt)
                ys.append(plant.outputs())
            runs.append(np.array(ys))
        h[:, :, j] = (runs[0] - runs[1]) / (2.0 * delta)
    plant.restore_state(start)
    return h


def realize(h: np.ndarray, *, rtol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ho-Kalman / ERA: a minimal ``(A, B, C)`` with ``C A^(k-1) B = h[k-1]``; also the Hankel singular values.

    Parameters
    ----------
    h : ndarray, shape (N, p, m)
        Markov parameters ``h_1 .. h_N``.
    rtol : float
        Singular values below ``rtol`` times the largest are taken as zero (they set the order).
    """
    N, p, m = h.shape
    rows = N // 2
    cols = N - rows - 1
    H0 = np.block([[h[i + j] for j in range(cols)] for i in range(rows)])
    H1 = np.block([[h[i + j + 1] for j in range(cols)] for i in range(rows)])
    U, s, Vt = np.linalg.svd(H0, full_matrices=False)
    if s.size == 0 or s[0] == 0.0:
        return np.zeros((0, 0)), np.zeros((0, m)), np.zeros((p, 0)), s
    n = int(np.sum(s > rtol * s[0]))
    Un, Vn, root = U[:, :n], Vt[:n, :].T, np.sqrt(s[:n])
    A = (Un / root).T @ H1 @ (Vn / root)
    B = (root[:, None] * Vn.T)[:, :m]
    C = (Un * root)[:p, :]
    return A, B, C, s


def identify_cosimulation(
    path: Path,
    *,
    md: Any,
    at: Mapping[str, float],
    inputs: list[str] | None,
    outputs: list[str] | None,
    Ts: float,
    horizon: int = DEFAULT_HORIZON,
    rel_step: float = 1e-4,
    rtol: float = 1e-8,
    max_misfit: float = 1e-6,
) -> dict:
    """Discrete ``A, B, C, D`` of a Co-Simulation FMU at step ``Ts`` about the point ``at``.

    Parameters
    ----------
    path : Path
        The FMU.
    md : fmpy ModelDescription
        Its model description (read by the caller).
    at : mapping
        Input values (held) and parameter start values at the operating point; the rest keep their start values.
    inputs, outputs : list of str, optional
        The Real inputs and outputs to keep (default: the declared ones).
    Ts : float
        The communication step, which becomes the spec's sample time.
    horizon : int
        Steps recorded per pulse (the realisation's order is at most about ``horizon / 2`` times min(m, p)).
    rel_step, rtol
        Pulse size (relative to ``max(1, |u0|)``) and the Hankel singular-value cut.
    max_misfit : float
        Largest misfit of the realised model's Markov parameters over the horizon (relative to the largest
        measured one) before the identification is refused.

    Returns
    -------
    dict
        ``A, B, C, D, inputs, outputs, states, u0, y0, hankel`` (the singular values), ``fit`` (largest
        misfit of the realised Markov parameters, relative to the largest).
    """
    _check_identifiable(md, Ts)
    h, u0, y0, names = _measure(path, md=md, at=at, inputs=inputs, outputs=outputs, Ts=Ts, horizon=horizon,
                                rel_step=rel_step)  # fmt: skip
    A, B, C, s = realize(h, rtol=rtol)
    fit = _checked_realisation(md, h, A, B, C, horizon=horizon, Ts=Ts, max_misfit=max_misfit)
    n = A.shape[0]
    return {
        "A": A,
        "B": B,
        "C": C,
        "D": np.zeros((C.shape[0], B.shape[1])),
        "inputs": names[0],
        "outputs": names[1],
        "states": tuple(f"x{i}" for i in range(n)),
        "u0": u0,
        "y0": y0,
        "hankel": s,
        "fit": fit,
    }


def _check_identifiable(md: Any, Ts: float) -> None:
    """The FMU can save its state (pulses start from one saved state) and the step is positive."""
    if not md.coSimulation.canGetAndSetFMUstate:
        raise PlantError(
            f"FMU {md.modelName} is Co-Simulation only and cannot save its state "
            "(canGetAndSetFMUstate=false): linearize perturbs doStep from one saved state and needs it"
        )
    if not (Ts > 0 and np.isfinite(Ts)):
        raise PlantError("linearize: the step (--Ts) must be positive")


def _measure(
    path: Path,
    *,
    md: Any,
    at: Mapping[str, float],
    inputs: list[str] | None,
    outputs: list[str] | None,
    Ts: float,
    horizon: int,
    rel_step: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[list[str], list[str]]]:
    """Pulse responses of the FMU about the point, with the inputs and outputs there and the signal names."""
    real = "Float64" if md.fmiVersion == "3.0" else "Real"
    declared_in = [v.name for v in md.modelVariables if v.causality == "input" and v.type == real]
    in_names = list(inputs) if inputs else declared_in
    at_inputs = {k: float(v) for k, v in at.items() if k in in_names}
    params = {k: float(v) for k, v in at.items() if k not in in_names}
    plant = FmuPlant(path=path, inputs=in_names, outputs=outputs or None, parameters=params)
    try:
        starts = {v.name: v.start for v in md.modelVariables}
        u0 = np.array([at_inputs.get(n, float(starts.get(n) or 0.0)) for n in plant.input_names])
        y0 = plant.outputs()
        h = _pulse_responses(plant, u0=u0, dt=float(Ts), horizon=horizon, rel_step=rel_step)
    finally:
        plant.close()
    return h, u0, y0, (plant.input_names, plant.output_names)


def _checked_realisation(
    md: Any,
    h: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    *,
    horizon: int,
    Ts: float,
    max_misfit: float,
) -> float:
    """The realisation's misfit to the measured Markov parameters, or PlantError when it cannot be trusted."""
    n = A.shape[0]
    if n == 0:
        raise PlantError(
            f"FMU {md.modelName}: no input moves an output within {horizon} steps of {Ts:g}; "
            "nothing to identify (a longer --horizon or other inputs/outputs?)"
        )
    if n >= min(h.shape[0] // 2 * h.shape[1], (h.shape[0] - h.shape[0] // 2 - 1) * h.shape[2]):
        raise PlantError(
            f"FMU {md.modelName}: the response needs more states than {horizon} steps can show (raise --horizon)"
        )
    pred = np.array([C @ np.linalg.matrix_power(A, k) @ B for k in range(h.shape[0])])
    fit = float(np.max(np.abs(pred - h)) / np.max(np.abs(h)))
    if fit > max_misfit:
        raise PlantError(
            f"FMU {md.modelName}: an order-{n} model misses the measured step responses by {fit:.2g} of "
            f"their size (more than {max_misfit:g}): the horizon of {horizon} steps is too short "
            "(raise --horizon) or the FMU is not linear/time-invariant about this point"
        )
    return fit
