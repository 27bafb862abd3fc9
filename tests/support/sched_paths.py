"""An oracle for a scheduled law under a moving sigma, independent of ``gainlink.synthesis``: the unsaturated
velocity-form loop written out here from the law's step (docs/design.md, scheduled law) on the artifact's own
per-point numbers (the JSON, interpolated here), and periodic sigma paths (holds, jumps, ramps) searched here.

A periodic sigma path grows exactly when the spectral radius of the loop's transition over one period is at least
one; ``growth`` is that radius per step.
"""

from __future__ import annotations

import itertools

import numpy as np


class LoopModel:
    """The velocity loop of a scheduled artifact dict: plant ``x``, law ``delta``, ``u_prev``, ``y_prev``,
    ``e_prev``; references zero, no saturation, the plant interpolated at the sigma the law uses."""

    def __init__(self, data: dict) -> None:
        sch = data["schedule"]
        self.points = np.array(sch["points"], dtype=float)
        pts = sch["point"]
        self.mats = {k: np.array([np.array(p[k], dtype=float) for p in pts])
                     for k in ("Ad", "Bd", "Cd", "Dd", "Kx", "Ky", "Kz", "F", "G", "Ly")}  # fmt: skip
        self.Ci = np.array(data["Ci"], dtype=float)
        n, m = self.mats["Bd"].shape[1:]
        p, q = self.mats["Cd"].shape[1], self.Ci.shape[0]
        self.sizes = (n, n, m, p, q)
        self._cache: dict[float, np.ndarray] = {}

    def at(self, sigma: float) -> dict[str, np.ndarray]:
        """Every matrix interpolated linearly at sigma (clipped into the envelope)."""
        s = min(max(float(sigma), self.points[0]), self.points[-1])
        i = min(int(np.searchsorted(self.points, s, side="right")) - 1, len(self.points) - 2)
        lam = (s - self.points[i]) / (self.points[i + 1] - self.points[i])
        return {k: v[i] + lam * (v[i + 1] - v[i]) for k, v in self.mats.items()}

    def step_matrix(self, sigma: float) -> np.ndarray:
        """The loop's transition at sigma, column by column: one step of the law's equations on each unit state."""
        key = float(sigma)
        if key not in self._cache:
            c = self.at(sigma)
            N = sum(self.sizes)
            cols = []
            for z in np.eye(N):
                x, d, up, yp, ep = np.split(z, np.cumsum(self.sizes)[:-1])
                du = -c["Kx"] @ d - c["Ky"] @ (c["Cd"] @ x - yp) - c["Kz"] @ ep
                u = up + du
                y = c["Cd"] @ x + c["Dd"] @ u
                cols.append(np.concatenate([c["Ad"] @ x + c["Bd"] @ u, c["F"] @ d + c["G"] @ du + c["Ly"] @ (y - yp),
                                            u, y, -self.Ci @ y]))  # fmt: skip
            self._cache[key] = np.array(cols).T
        return self._cache[key]

    def growth(self, path: np.ndarray) -> float:
        """Spectral radius per step of the transition over one period of ``path`` (renormalised as it goes)."""
        Z, log_norm = np.eye(sum(self.sizes)), 0.0
        for s in path:
            Z = self.step_matrix(s) @ Z
            norm = np.linalg.norm(Z)
            if norm == 0.0:
                return 0.0
            Z, log_norm = Z / norm, log_norm + np.log(norm)
        rho = np.max(np.abs(np.linalg.eigvals(Z)))
        return 0.0 if rho == 0.0 else float(np.exp((np.log(rho) + log_norm) / len(path)))


def hold_ramp_hold(a: float, b: float, d1: int, d2: int, step: float) -> np.ndarray:
    """One period: ``a`` for ``d1`` samples, up to ``b`` by at most ``step`` per sample, ``b`` for ``d2``, back."""
    k = int(np.ceil((b - a) / step - 1e-12))
    inside = a + step * np.arange(1, k)
    return np.concatenate([np.full(d1, a), inside, np.full(d2, b), inside[::-1]])


def adversarial(model: LoopModel, step: float, *, levels: int = 6, dwells=(1, 2, 3, 5, 8, 12, 17, 23, 30, 40)):
    """The worst ``(growth, path)`` over holds, jumps and ramps at ``step`` per sample between every pair of
    ``levels`` equally spaced levels of the envelope, each level held for every pair of ``dwells``."""
    grid = np.linspace(model.points[0], model.points[-1], levels)
    worst: tuple[float, np.ndarray | None] = (0.0, None)
    for a, b in itertools.combinations(grid, 2):
        for d1, d2 in itertools.product(dwells, repeat=2):
            path = hold_ramp_hold(a, b, d1, d2, step)
            g = model.growth(path)
            if g > worst[0]:
                worst = (g, path)
    return worst
