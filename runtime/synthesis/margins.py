"""Loop-at-a-time margins at each plant input (the loop broken where an actuator would change it) and the
closed-loop bandwidth they imply."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .analysis import pole_frequency
from .discretize import Discretised
from .loop import closed_loop_matrix

MARGIN_GRID_POINTS = 2000


@dataclass(frozen=True)
class ChannelMargin:
    """Loop-at-a-time margins with the loop broken at one plant input (others closed).

    Gain margins are exact: the factors by which that loop's gain can rise or fall before an
    eigenvalue of the closed loop leaves the unit circle (``None``: beyond 60 dB either way).
    The phase margin and the gain crossover come from the loop's frequency response.
    """

    input: str
    gain_margin_up_db: float | None
    gain_margin_down_db: float | None
    phase_margin_deg: float | None
    gain_crossover_rad_s: float | None


def input_margins(d: Discretised, *, K, Ki, L, M, Ci, Ts, form, inputs) -> list[ChannelMargin]:
    """Loop-at-a-time gain and phase margins at each plant input (others closed)."""
    out = []
    for i, name in enumerate(inputs):
        A, B, C = closed_loop_matrix(d, K=K, Ki=Ki, L=L, M=M, Ci=Ci, Ts=Ts, form=form, break_input=i)
        out.append(broken_loop_margin(name, A, B, C, Ts))
    return out


def broken_loop_margin(name: str, A: np.ndarray, B: np.ndarray, C: np.ndarray, Ts: float) -> ChannelMargin:
    """Gain and phase margins of the loop ``(A, B, C)`` broken at input ``name`` (loop gain ``-C (zI - A)^-1 B``)."""
    pm, wgc = _phase_margin(A, B, C, Ts)
    up = _gain_limit(A, B @ C, direction=+1)
    down = _gain_limit(A, B @ C, direction=-1)
    return ChannelMargin(
        input=name,
        gain_margin_up_db=None if up is None else float(20 * np.log10(up)),
        gain_margin_down_db=None if down is None else float(20 * np.log10(down)),
        phase_margin_deg=pm,
        gain_crossover_rad_s=wgc,
    )


def _phase_margin(A: np.ndarray, B: np.ndarray, C: np.ndarray, Ts: float) -> tuple[float | None, float | None]:
    """Smallest phase margin over the 0 dB crossings of the loop gain ``-C (zI - A)^-1 B``, and where.

    The response is evaluated on a dense log grid up to Nyquist in one batched solve; each crossing
    is located by interpolating log|L| against log w and the phase taken there exactly. (python-control's
    default 'poly' method roots a high-order polynomial and misplaces crossovers for loops this size.)
    """
    n = A.shape[0]

    def response(w: np.ndarray) -> np.ndarray:
        z = np.exp(1j * w * Ts)
        return -(C @ np.linalg.solve(z[:, None, None] * np.eye(n) - A, B))[:, 0, 0]

    w_nyquist = np.pi / Ts
    grid = np.logspace(np.log10(w_nyquist) - 6, np.log10(w_nyquist), MARGIN_GRID_POINTS)
    with np.errstate(all="ignore"):
        log_mag = np.log(np.abs(response(grid)))
    crossings = np.flatnonzero(np.isfinite(log_mag[:-1]) & (log_mag[:-1] * log_mag[1:] < 0))
    if crossings.size == 0:
        return None, None
    i = crossings
    frac = log_mag[i] / (log_mag[i] - log_mag[i + 1])
    w_c = np.exp(np.log(grid[i]) + frac * (np.log(grid[i + 1]) - np.log(grid[i])))
    margins = 180.0 - np.abs(np.degrees(np.angle(response(w_c))))
    k = int(np.argmin(margins))
    return float(margins[k]), float(w_c[k])


GRID_STEP_DB = 0.25  # the scan for the first unstable gain, before the bisection
SCAN_CHUNK = 24  # grid gains whose eigenvalues are computed in one call (6 dB)
BISECTION_RTOL = 1e-10


def _gain_limit(A: np.ndarray, BC: np.ndarray, *, direction: int, max_db: float = 60.0) -> float | None:
    """The loop-gain factor k (above or below 1) at which ``A + k BC`` first loses stability: the first unstable
    gain of a quarter-dB grid (its eigenvalues a chunk at a time), then bisection between it and the one before."""

    def radii(ks: np.ndarray) -> np.ndarray:
        return np.max(np.abs(np.linalg.eigvals(A + ks[:, None, None] * BC)), axis=1)

    grid = 10 ** (direction * GRID_STEP_DB * np.arange(1, int(round(max_db / GRID_STEP_DB)) + 1) / 20)
    inside = 1.0
    for start in range(0, grid.size, SCAN_CHUNK):
        ks = grid[start : start + SCAN_CHUNK]
        unstable = np.flatnonzero(radii(ks) >= 1.0)
        if unstable.size:
            j = start + int(unstable[0])
            inside, outside = (grid[j - 1] if j else 1.0), float(grid[j])
            break
    else:
        return None
    while abs(outside / inside - 1.0) > BISECTION_RTOL:
        mid = np.sqrt(inside * outside)
        inside, outside = (mid, outside) if radii(np.array([mid]))[0] < 1.0 else (inside, mid)
    return float(outside)


def loop_bandwidth(margins: list[ChannelMargin], controller_poles: np.ndarray, Ts: float) -> float:
    """Closed-loop bandwidth proxy: the highest gain crossover at the plant inputs.

    Falls back to the fastest controller pole when no loop crosses 0 dB.
    """
    crossings = [mg.gain_crossover_rad_s for mg in margins if mg.gain_crossover_rad_s]
    if crossings:
        return float(max(crossings))
    return max(pole_frequency(z, discrete=True, Ts=Ts) for z in controller_poles)
