"""What a scheduled run's report says about sigma (:mod:`.sil_scheduled`): where it went, how fast, and how often
the law held, clipped or rate-limited it."""

from __future__ import annotations

from typing import Any

import numpy as np
from gainlink.proof.scheduled_reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE


def schedule_metrics(trace: Any, *, artifact: Any) -> dict:
    """The ``schedule`` block of a scheduled run's metrics.

    ``sigma_min``/``sigma_max`` the range sigma covered, ``coverage`` that range over the envelope's (1: all of
    it), ``max_rate`` the fastest ``|d sigma / dt|`` between steps (per second), ``held_steps``, ``clipped_steps``,
    ``rate_limited_steps`` the steps with each flag, and the schedule's ``sigma``, ``source``, ``points``,
    ``rate_max`` and ``rate_certified`` (whether a Lyapunov certificate covers that rate) for the record.
    """
    S = artifact.schedule
    sigma = np.asarray(trace.sigma, dtype=float)
    flags = np.asarray(trace.sigma_flags, dtype=int)
    lo, hi = (float(sigma.min()), float(sigma.max())) if sigma.size else (None, None)
    span = float(S.points[-1] - S.points[0])
    rate = float(np.max(np.abs(np.diff(sigma)), initial=0.0) / artifact.Ts)
    return {
        "sigma": S.sigma,
        "source": S.source,
        "points": [float(v) for v in S.points],
        "rate_max": S.rate_max,
        "rate_certified": S.rate_certified,
        "sigma_min": lo,
        "sigma_max": hi,
        "coverage": (hi - lo) / span if sigma.size else 0.0,
        "max_rate": rate,
        "held_steps": int(np.count_nonzero(flags & SIGMA_HELD)),
        "clipped_steps": int(np.count_nonzero(flags & SIGMA_CLIPPED)),
        "rate_limited_steps": int(np.count_nonzero(flags & SIGMA_RATE)),
    }
