"""The scheduled law frozen on a dense grid of sigma (at least :data:`GRID_PER_INTERVAL` steps per interval, the
points included): closed-loop stability and the loop-at-a-time margins at each plant input, as the design checks
one point. The law there is the interpolated coefficients (the law the C runs), the plant the interpolated
sampled plants."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ...errors import DesignError
from ...synthesis.margins import ChannelMargin, broken_loop_margin
from .block import Schedule
from .lpv import frozen_loop

GRID_PER_INTERVAL = 10


@dataclass(frozen=True)
class GridCheck:
    """Every grid sigma with its closed-loop spectral radius and margins, and the worst of each."""

    sigma: np.ndarray
    radius: np.ndarray
    margins: list[list[ChannelMargin]]

    @property
    def worst_sigma(self) -> float:
        """Where the spectral radius is largest."""
        return float(self.sigma[int(np.argmax(self.radius))])

    def smallest(self, field: str) -> float | None:
        """The smallest of a margin field over the grid and the inputs (None: none finite)."""
        values = [getattr(mg, field) for row in self.margins for mg in row if getattr(mg, field) is not None]
        return float(min(values)) if values else None

    def to_dict(self) -> dict:
        """The record in ``checks.schedule.grid``."""
        return {
            "per_interval": GRID_PER_INTERVAL,
            "sigma_count": int(self.sigma.size),
            "max_spectral_radius": float(self.radius.max()),
            "worst_sigma": self.worst_sigma,
            "min_gain_margin_up_db": self.smallest("gain_margin_up_db"),
            "min_gain_margin_down_db": self.largest_down(),
            "min_phase_margin_deg": self.smallest("phase_margin_deg"),
            "stable": bool(self.radius.max() < 1.0),
        }

    def largest_down(self) -> float | None:
        """The gain-reduction margin closest to 0 dB (the largest of these negative numbers), None: none finite."""
        values = [mg.gain_margin_down_db for row in self.margins for mg in row if mg.gain_margin_down_db is not None]
        return float(max(values)) if values else None


def grid(points: np.ndarray, per_interval: int = GRID_PER_INTERVAL) -> np.ndarray:
    """``per_interval`` equal steps across each interval, the points included."""
    parts = [np.linspace(a, b, per_interval + 1)[:-1] for a, b in itertools.pairwise(points)]
    return np.concatenate(parts + [points[-1:]])


def grid_check(s: Schedule, *, Ci: np.ndarray, Ts: float, inputs: tuple[str, ...]) -> GridCheck:
    """Stability and margins of the frozen scheduled loop at every grid sigma; DesignError at the first unstable."""
    sigmas = grid(s.points)
    radius, margins = [], []
    for sigma in sigmas:
        plant, c = s.plant_at(sigma), s.coefficients_at(sigma)
        r = float(np.max(np.abs(np.linalg.eigvals(frozen_loop(plant, c, Ci=Ci, Ts=Ts)))))
        if not r < 1.0:
            raise DesignError(
                f"the scheduled law is unstable frozen at sigma = {sigma:.6g} between the points (closed-loop "
                f"spectral radius {r:.6g}): add a point there"
            )
        radius.append(r)
        margins.append(
            [
                broken_loop_margin(name, *frozen_loop(plant, c, Ci=Ci, Ts=Ts, break_input=i), Ts)
                for i, name in enumerate(inputs)
            ]
        )
    return GridCheck(sigma=sigmas, radius=np.array(radius), margins=margins)
