"""The verdict on a moving sigma: a common quadratic Lyapunov function (any rate), else the rate a sigma-dependent
one certifies, and the fastest rate that stays stable in simulation; and from them the ``rate_max`` the law
enforces (docs/design.md, scheduled law)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..shipping.artifact import matrix_to_json
from ..shipping.scheduled import Schedule
from .lpv import bernstein_vertices, lambda_polynomial, velocity_loop
from .lyapunov import Certificate, common_lyapunov, rate_certificate
from .schedule_rate import RateScan, scan_rates
from .schedule_sweeps import SWEEP_PIECES

#: Each interval is split in this many parts for the Bernstein hull (a tighter hull, more vertices).
HULL_PIECES = 2


@dataclass(frozen=True)
class VariationCheck:
    """``common``: a common P (stable at any rate) or None; ``certified``: the rate a P(sigma) certifies (when no
    common P); ``scan``: the simulation; ``rate_max``: what the law enforces and ``rate_max_source`` why."""

    common: Certificate | None
    certified: Certificate | None
    scan: RateScan
    rate_max: float | None
    rate_max_source: str

    def to_dict(self) -> dict:
        """The record in ``checks.schedule.variation``."""
        cert = self.common or self.certified
        return {
            "method": "quadratic Lyapunov function over the Bernstein hull of the velocity loop on each interval "
            f"({HULL_PIECES} pieces per interval), re-checked by eigenvalues; periodic sigma trajectories (triangles "
            f"between every pair of {SWEEP_PIECES + 1} envelope nodes, the points and the intervals' middles; "
            "rate-limited steps across the envelope) judged by their monodromy matrix on a log grid of rates",
            "common_lyapunov": self.common is not None,
            "certified_rate": None if self.certified is None else self.certified.rate,
            "certificate_margin": None if cert is None else cert.margin,
            "solver": None if cert is None else cert.solver,
            "simulated_stable_rate": self.scan.stable_rate,
            "simulated_rates": int(self.scan.rates.size),
            "simulated_max_radius_at_stable_rate": _radius_at(self.scan),
            "rate_max": self.rate_max,
            "rate_max_source": self.rate_max_source,
            "confirmed_by_simulation": _confirmed(self),
            "certificate": None if cert is None else _certificate_record(cert),
        }


def _certificate_record(cert: Certificate) -> dict:
    """The Lyapunov matrices themselves, so that anyone can re-check them: P at each node (one: a common P)."""
    return {"nodes": [float(v) for v in cert.nodes], "P": [matrix_to_json(P) for P in cert.P]}


def _radius_at(scan: RateScan) -> float | None:
    ok = scan.radius[scan.radius < 1.0]
    return float(ok[-1]) if ok.size else None


def _confirmed(v: VariationCheck) -> bool:
    """The simulation found nothing unstable at or below the rate the verdict allows."""
    if v.scan.stable_rate is None:
        return True
    return v.rate_max is not None and v.rate_max <= v.scan.stable_rate


def loops_at(s: Schedule, Ci: np.ndarray):
    """``sigmas (K,) -> velocity loop matrices (K, N, N)`` through the loop's polynomial in lambda on each
    interval (the same matrices as :func:`~.lpv.velocity_loop` at each sigma, fast to evaluate in bulk)."""
    polys = np.array([lambda_polynomial(_interval_fn(s, Ci, i)) for i in range(len(s.points) - 1)])
    degree = polys.shape[1] - 1

    def at(sigmas: np.ndarray) -> np.ndarray:
        clipped = np.clip(sigmas, s.points[0], s.points[-1])
        i = np.clip(np.searchsorted(s.points, clipped, side="right") - 1, 0, len(s.points) - 2)
        lam = (clipped - s.points[i]) / (s.points[i + 1] - s.points[i])
        return np.einsum("kj,kjab->kab", lam[:, None] ** np.arange(degree + 1), polys[i])

    return at


def _interval_fn(s: Schedule, Ci: np.ndarray, i: int, a: float = 0.0, b: float = 1.0):
    lo, hi = s.points[i], s.points[i + 1]

    def fn(t: float) -> np.ndarray:
        sigma = lo + (a + (b - a) * t) * (hi - lo)
        return velocity_loop(s.plant_at(sigma), s.coefficients_at(sigma), Ci=Ci)

    return fn


def hull(s: Schedule, Ci: np.ndarray) -> tuple[np.ndarray, list[list[np.ndarray]]]:
    """Nodes (points and piece boundaries) and, per piece, the Bernstein vertices of the velocity loop."""
    nodes, pieces = [], []
    for i in range(len(s.points) - 1):
        for j in range(HULL_PIECES):
            a, b = j / HULL_PIECES, (j + 1) / HULL_PIECES
            nodes.append(s.points[i] + a * (s.points[i + 1] - s.points[i]))
            pieces.append(bernstein_vertices(_interval_fn(s, Ci, i, a, b)))
    return np.array(nodes + [s.points[-1]]), pieces


def variation_check(s: Schedule, *, Ci: np.ndarray, Ts: float, spec_rate_max: float | None) -> VariationCheck:
    """Common P, else certified rate; the simulated scan; ``rate_max`` = the spec's, tightened to the certified
    rate (or, with no certificate at all, to the simulated stable rate)."""
    nodes, pieces = hull(s, Ci)
    common = common_lyapunov([V for piece in pieces for V in piece])
    scan = scan_rates(loops_at(s, Ci), s.points, Ts)
    certified = None
    if common is None:
        unstable = scan.rates[-1] if scan.stable_rate is not None else float(s.points[-1] - s.points[0]) / Ts
        certified = rate_certificate(nodes, pieces, Ts=Ts, rate_hi=float(unstable))
    if common is not None:
        bound, source = None, "common Lyapunov function: any rate"
    elif certified is not None:
        bound, source = certified.rate, "certified rate (sigma-dependent Lyapunov function)"
    else:
        bound, source = scan.stable_rate, "simulation (no Lyapunov certificate found)"
    rate_max = _tighter(spec_rate_max, bound)
    if spec_rate_max is not None and rate_max == spec_rate_max:
        source = "spec" + ("" if bound is None else f" (within the {source.split(' (')[0]})")
    return VariationCheck(common=common, certified=certified, scan=scan, rate_max=rate_max, rate_max_source=source)


def _tighter(a: float | None, b: float | None) -> float | None:
    values = [v for v in (a, b) if v is not None]
    return min(values) if values else None
