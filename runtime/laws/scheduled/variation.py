"""The verdict on a moving sigma (docs/design.md, scheduled law): what is proved about the loop while sigma moves,
what the falsifier found, and from them the ``rate_max`` the law enforces and whether it is certified.

In order: the loop frozen anywhere in the envelope is proved stable piece by piece (else the design is refused,
naming where); the falsifier scans periodic sigma paths (:mod:`.rate`) for the first rate at which one
grows; a common ``P`` proves any rate; else the fastest rate a ``P(sigma)`` proves, below the falsifier's rate, is
searched within the budget (:mod:`.certify`). The shipped ``rate_max`` is a certified rate (rounded down
to three digits), the spec's when slower; or, when the spec declares its own rate uncertified
(``rate_certified = false``), the spec's, said to be not certified. A path the falsifier finds growing at or below a
certified rate contradicts the certificate: :class:`CertificateContradiction`, never an artifact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import DesignError, VerificationError
from .block import Schedule
from .certify import (
    MAX_PIECES,
    REFINEMENTS,
    Budget,
    RateSearch,
    certify_rate,
    common,
    prove_frozen,
    start_pieces,
)
from .hull import LoopHull
from .lpv import loop_polynomial
from .lyapunov import PREC, Certificate
from .rate import Path, RateScan, dwell_grid, scan_rates, worst_path

#: CPU seconds the certificate searches may take by default (``[schedule] certify_budget``).
DEFAULT_BUDGET = 60.0
#: A certified rate at which sigma needs longer than this many slowest closed-loop time constants to cross the
#: envelope is shipped with a warning saying that time.
CROSSING_TIME_CONSTANTS = 100.0

COVERS = (
    "the unsaturated velocity-form loop on the interpolated linear plant, the law's coefficients interpolated "
    "exactly from the artifact's float64 points, references zero; any sigma path whose steps are at most "
    "Ts * rate_max (sigma clipped to the envelope); not saturation, the float32 C or the plant's nonlinearity"
)


class CertificateContradiction(VerificationError):
    """The falsifier found a path growing at or below a certified rate: the certificate is wrong (a bug in
    gainlink, reported in one line like every refusal; no artifact is written)."""


@dataclass(frozen=True)
class VariationCheck:
    """The verdict: the frozen proof, a common ``P`` (any rate) or the rate search, the falsifier's scan and its
    worst path at the shipped rate, and the ``rate_max`` shipped, whether it is certified and why."""

    frozen: list[Certificate]
    common: Certificate | None
    search: RateSearch | None
    scan: RateScan
    at_rate_max: Path | None
    rate_max: float | None
    rate_certified: bool
    rate_source: str
    budget: float

    @property
    def certified_rate(self) -> float | None:
        """The fastest rate proved (None: none, or any rate with a common ``P``)."""
        cert = None if self.search is None else self.search.certificate
        return None if cert is None else cert.rate

    def to_dict(self) -> dict:
        """The record in ``checks.schedule.variation``."""
        cert = self.common or (None if self.search is None else self.search.certificate)
        return {
            "method": _method_text(),
            "covers": COVERS,
            "frozen": {
                "certified": True,
                "pieces": len(self.frozen),
                "certificates": [c.to_dict() for c in self.frozen],
            },
            "common_lyapunov": self.common is not None,
            "certified_rate": _shipped(self.certified_rate),
            "rate_max": self.rate_max,
            "rate_certified": self.rate_certified,
            "rate_source": self.rate_source,
            "certificate": None if cert is None else cert.to_dict(),
            "search": None if self.search is None else _search_record(self.search, self.budget),
            "falsifier": _falsifier_record(self.scan, self.at_rate_max),
        }


def _method_text() -> str:
    return (
        "Lyapunov functions x' P x on the loop's states [x; delta; u_prev; y_prev] (e_prev = -Ci y_prev after the "
        "first step): the loop's exact polynomial in lambda on each interval hulled by its Bernstein coefficients on "
        "dyadic pieces; frozen: one P per piece; any rate: one P; a rate: P(sigma) piecewise linear between nodes, "
        "P(s) - V' P(s') V > 0 at every corner of every piece against every node interval within Ts * rate; found by "
        f"Clarabel, proved in ball arithmetic (python-flint arb, {PREC} bits, Rump's test) on the exact vertices, at "
        "exact rational corners. Falsifier (never a proof): periodic sigma paths (triangles and dwells between "
        "levels) judged by their monodromy matrices"
    )


def _search_record(search: RateSearch, budget: float) -> dict:
    return {
        "budget_s": budget,
        "budget_spent": search.budget_spent,
        "lmis_solved": search.solves,
        "hull_pieces": len(search.pieces),
        "max_pieces": MAX_PIECES,
        "refinements_max": REFINEMENTS,
        "slowest_rate_not_proved": search.unproved,
    }


def _falsifier_record(scan: RateScan, at_rate_max: Path | None) -> dict:
    return {
        "rates_tried": int(scan.rates.size),
        "first_growing_rate": scan.unstable_rate,
        "worst": scan.worst.to_dict(),
        "at_rate_max": None if at_rate_max is None else at_rate_max.to_dict(),
        "dwells": list(scan.dwells),
    }


def loops_at(s: Schedule, Ci: np.ndarray):
    """``sigmas (K,) -> velocity loop matrices (K, N, N)`` from the loop's exact polynomial in lambda on each
    interval (the matrices of :func:`~.lpv.velocity_loop` at each sigma, fast to evaluate in bulk)."""
    polys = [loop_polynomial(s, Ci, i) for i in range(len(s.points) - 1)]
    degree = max(len(p) for p in polys) - 1
    stack = np.array([np.concatenate([p, np.zeros((degree + 1 - len(p),) + p.shape[1:])]) for p in polys])

    def at(sigmas: np.ndarray) -> np.ndarray:
        clipped = np.clip(sigmas, s.points[0], s.points[-1])
        i = np.clip(np.searchsorted(s.points, clipped, side="right") - 1, 0, len(s.points) - 2)
        lam = (clipped - s.points[i]) / (s.points[i + 1] - s.points[i])
        return np.einsum("kj,kjab->kab", lam[:, None] ** np.arange(degree + 1), stack[i])

    return at


@dataclass(frozen=True)
class RateSpec:
    """What the spec says of sigma's rate: ``rate_max`` (None: none), whether it must be certified, the budget."""

    rate_max: float | None = None
    certified: bool = True
    budget: float = DEFAULT_BUDGET


def variation_check(s: Schedule, *, Ci: np.ndarray, Ts: float, tau_samples: float, spec: RateSpec,
                    sigma: str) -> VariationCheck:  # fmt: skip
    """The verdict (module docstring); DesignError when nothing certifies and the spec did not declare its rate
    uncertified."""
    budget = Budget(spec.budget)
    hull = LoopHull.of(s, Ci)
    frozen_pieces, frozen = prove_frozen(hull, budget, sigma=sigma)
    L = loops_at(s, Ci)
    scan = scan_rates(L, s.points, Ts, dwell_grid(tau_samples))
    any_rate = common(hull, frozen_pieces)
    if any_rate is not None and scan.unstable_rate is not None:
        raise CertificateContradiction(f"a common Lyapunov function was proved but {scan.worst.describe(sigma)}")
    search = None
    if any_rate is None:
        ceiling = scan.unstable_rate or float(s.points[-1] - s.points[0]) / Ts
        search = certify_rate(hull, start_pieces(hull, frozen_pieces), Ts=Ts, hi=ceiling, budget=budget)
    rate_max, certified, source = _decide(any_rate, search, spec, sigma=sigma)
    at_rate_max = None
    if certified and rate_max is not None:
        at_rate_max = worst_path(L, s.points, Ts, rate_max, scan.dwells)
        if at_rate_max.growth >= 1.0:
            raise CertificateContradiction(
                f"the rate {rate_max:.4g}/s of {sigma} is certified but {at_rate_max.describe(sigma)}"
            )
    return VariationCheck(frozen, any_rate, search, scan, at_rate_max, rate_max, certified, source, spec.budget)


def _decide(any_rate: Certificate | None, search: RateSearch | None, spec: RateSpec,
            *, sigma: str) -> tuple[float | None, bool, str]:  # fmt: skip
    """``(rate_max, certified, why)`` from the certificates and the spec (module docstring)."""
    if any_rate is not None:
        if spec.rate_max is None:
            return None, True, "any rate: a common Lyapunov function"
        return spec.rate_max, True, "the spec's; any rate is certified (a common Lyapunov function)"
    proved = _shipped(search.certificate.rate) if search and search.certificate else None
    if proved is not None and (spec.rate_max is None or spec.rate_max > proved):
        if spec.rate_max is not None and not spec.certified:
            return spec.rate_max, False, f"the spec's, declared not certified (certified up to {proved:.4g}/s)"
        above = "" if spec.rate_max is None else f"; the spec's {spec.rate_max:g}/s is above it"
        return proved, True, f"the fastest rate a sigma-dependent Lyapunov function proves, rounded down{above}"
    if proved is not None:
        return spec.rate_max, True, f"the spec's, within the certified {proved:.4g}/s"
    if spec.rate_max is not None and not spec.certified:
        return spec.rate_max, False, "the spec's, declared not certified (no rate certified)"
    where = search.binding.describe(sigma) if search and search.binding else f"the envelope of {sigma}"
    stop = " within the budget" if search and search.budget_spent else ""
    raise DesignError(
        f"no Lyapunov function certifies any rate of {sigma}{stop} (the search is stuck at {where}): declare a "
        "rate with [schedule] rate_max and rate_certified = false to ship it uncertified, or add points there"
    )


def _shipped(rate: float | None) -> float | None:
    """A proved rate rounded down to three significant digits (every slower rate is proved too)."""
    if rate is None or rate <= 0:
        return None
    scale = 10.0 ** (math.floor(math.log10(rate)) - 2)
    out = float(f"{math.floor(rate / scale) * scale:.3g}")
    while out > rate:  # the decimal's nearest double may lie an ulp above a rate that is exactly three digits
        out = float(f"{out - scale:.3g}")
    return out


def crossing_warning(v: VariationCheck, *, span: float, Ts: float, tau_samples: float, sigma: str) -> str | None:
    """The warning for a certified rate so slow that crossing the envelope takes longer than
    :data:`CROSSING_TIME_CONSTANTS` closed-loop time constants (None otherwise)."""
    if not v.rate_certified or v.rate_max is None:
        return None
    crossing, limit = span / v.rate_max, CROSSING_TIME_CONSTANTS * tau_samples * Ts
    if crossing <= limit:
        return None
    return (
        f"the certified rate of {sigma}, {v.rate_max:.4g}/s, needs {crossing:.4g} s to cross the envelope (more than "
        f"{CROSSING_TIME_CONSTANTS:g} closed-loop time constants, {limit:.3g} s)"
    )


def rate_text(rate_max: float | None, certified: bool) -> str:
    """``rate_max`` as every report prints it, with what covers it."""
    value = "not limited" if rate_max is None else f"{rate_max:.4g}/s"
    return f"{value}, {'certified' if certified else 'not certified'}"
