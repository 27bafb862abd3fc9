"""What a closed loop (:mod:`gainlink.hil.loop`) asks of the scheduled law beyond its step: the design's own model
at the sigma the law runs at (the model twin), what a run's report says about the artifact and about sigma, and the
probe without the rate limit."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .. import flags
from .block import interval, lerp
from .plant import ScheduledModel, operating_states


def design_model(
    artifact: Any, *, state: Mapping[str, float] | None, sigma: float
) -> tuple[ScheduledModel | None, str]:
    """The points' models interpolated at a moving sigma (:class:`~gainlink.laws.scheduled.plant.ScheduledModel`,
    which follows its law's sigma), started at the plant's ``state`` by name (absolute; else ``x_op`` at ``sigma``),
    and a note; ``(None, why)`` when the points give no ``x_op``."""
    X_op = operating_states(artifact)
    if X_op is None:
        return None, "off: the schedule's points give no x_op (the model's absolute state is unknown)"
    S = artifact.schedule
    i, lam = interval(S.points, S.clip(sigma))
    names = list(artifact.signals["states"])
    if state is not None and all(s in state for s in names):
        x0, note = np.array([state[s] for s in names]), "the plant's initial state (the model at the run's sigma)"
    else:
        x0, note = lerp(X_op, i, lam), "x_op at the start sigma (the plant's states do not map onto the model's)"
    return ScheduledModel(artifact, x_op=X_op, x0=x0, sigma=sigma), note


def describe(artifact: Any) -> dict:
    """A run report's schedule block of the artifact (and the rate limit a probe removed)."""
    S = artifact.schedule
    out: dict = {
        "schedule": {
            "sigma": S.sigma,
            "source": S.source,
            "points": [float(v) for v in S.points],
            "rate_max": S.rate_max,
            "rate_certified": S.rate_certified,
            "filter_tau": S.filter_tau,
        }
    }
    removed = artifact.data.get("provenance", {}).get("rate_limit_removed")
    if removed:  # sigma_rate_limit = false: the law runs without the designed rate_max
        out["rate_limit_removed"] = removed
    return out


def without_rate_limit(artifact: Any) -> Any:
    """A copy of a scheduled artifact whose law does not limit sigma's rate (``rate_max`` removed, re-sealed; its
    provenance's ``rate_limit_removed`` says which ``rate_max`` of which artifact): the scenario's
    ``sigma_rate_limit = false``. No certificate covers an unlimited rate unless one covered any rate already."""
    from ...shipping.artifact import from_dict, seal

    S = artifact.schedule
    certified = S.rate_certified and S.rate_max is None
    data = dict(artifact.data, schedule=dict(artifact.data["schedule"], rate_max=None, rate_certified=certified))
    removed = f"rate_max {artifact.schedule.rate_max!r} of sha256:{artifact.sha256}"
    data["provenance"] = dict(data.get("provenance", {}), rate_limit_removed=removed)
    return from_dict(seal(data))


def schedule_metrics(artifact: Any, trace: Any) -> dict:
    """The ``schedule`` block of a run's metrics: ``sigma_min``/``sigma_max`` the range sigma covered, ``coverage``
    that range over the envelope's (1: all of it), ``max_rate`` the fastest ``|d sigma / dt|`` between steps (per
    second), ``held_steps``, ``clipped_steps``, ``rate_limited_steps`` the steps with each flag, and the schedule's
    ``sigma``, ``source``, ``points``, ``rate_max`` and ``rate_certified`` (whether a Lyapunov certificate covers that
    rate) for the record."""
    S = artifact.schedule
    sigma = np.asarray(trace.sigma, dtype=float)
    bits = np.asarray(trace.flags, dtype=np.int64)
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
        "held_steps": int(np.count_nonzero(bits & flags.SIGMA_HELD)),
        "clipped_steps": int(np.count_nonzero(bits & flags.SIGMA_CLIPPED)),
        "rate_limited_steps": int(np.count_nonzero(bits & flags.SIGMA_RATE)),
    }


def schedule_lines(sch: Mapping[str, Any] | None) -> list[str]:
    """The summary's lines on sigma (nothing without a ``schedule`` block)."""
    if not sch:
        return []
    lo, hi = sch["points"][0], sch["points"][-1]
    return [
        f"  sigma {sch['sigma']} ({sch['source']}): covered [{sch['sigma_min']:.4g}, {sch['sigma_max']:.4g}] of "
        f"[{lo:.4g}, {hi:.4g}] ({100 * sch['coverage']:.0f}%), fastest {sch['max_rate']:.4g}/s"
        f" (rate_max {_rate(sch)}); steps held {sch['held_steps']},"
        f" clipped {sch['clipped_steps']}, rate-limited {sch['rate_limited_steps']}"
    ]


def _rate(sch: Mapping[str, Any]) -> str:
    """The law's rate_max with what covers it (a run recorded before ``rate_certified``: not certified)."""
    value = "none" if sch["rate_max"] is None else f"{sch['rate_max']:g}/s"
    return f"{value}, {'certified' if sch.get('rate_certified') else 'not certified'}"


def simulate(law: Any, artifact: Any, *, steps: int, x0: Any, reference: Any, noise_std: float, seed: int,
             signals: Any) -> Any:  # fmt: skip
    """The float64 scheduled law around the points' model (:class:`ScheduledModel`), which follows its own scheduled
    output or the external signals (as the scenario plant ``lpv_model``): started at ``x_op`` at the start
    sigma (the first point, or the first external signal) plus ``x0``; the reference holds the trim there unless
    given; the signals constant ((e,)) or per step ((steps, e))."""
    from ...errors import ArtifactError, DataError
    from ...proof.simulation import closed_loop

    a, sch = artifact, artifact.schedule
    if steps < 1:
        raise DataError("steps must be at least 1")
    e = len(sch.external)
    if e and signals is None:
        raise DataError(f"artifact {a.name} is scheduled on {sch.sigma}: give its external signal(s) ({e} value(s))")
    S = np.zeros((steps, e)) if signals is None else np.broadcast_to(np.asarray(signals, float), (steps, e))
    X_op = operating_states(a)
    if X_op is None:
        raise ArtifactError(f"artifact {a.name}: the schedule's points give no x_op, so its model's state is unknown")
    sigma0 = sch.clip(float(S[0, sch.index])) if sch.source == "external" else float(sch.points[0])
    i, lam = interval(sch.points, sigma0)
    start = lerp(X_op, i, lam) + (0.0 if x0 is None else np.asarray(x0, dtype=float).reshape(a.n))
    model = ScheduledModel(a, x_op=X_op, x0=start, sigma=sigma0)
    r = law.r_op(a, sigma=sigma0) if reference is None else np.asarray(reference, float).reshape(a.q)
    noise = noise_std * np.random.default_rng(seed).standard_normal((steps, a.p))

    def before(s: np.ndarray) -> None:  # an external sigma: the model's dynamics follow the signal
        if sch.source == "external":
            model.follow(sch.clip(float(s[sch.index])))

    def after() -> None:  # a measured sigma: the model's own output
        if sch.source == "output":
            model.follow(sch.clip(float(model.outputs()[sch.index])))

    after()
    return closed_loop(law.reference(a), model, Ts=a.Ts, m=a.m, R=np.tile(r, (steps, 1)), noise=noise, S=np.array(S),
                       before=before, after=after)  # fmt: skip
