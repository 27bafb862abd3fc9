"""Run metrics: timing (latency, jitter, deadline misses), link (lost, late), control (saturation,
integrator, overshoot, settling time, IAE)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from gainlink.laws import flags
from gainlink.proof.twin import twin_comparison

from .model_twin import model_mismatch


@dataclass(frozen=True)
class RunTrace:
    """Everything recorded per step of a run (row k = sample k), the same for every law and endpoint.

    ``t`` plant time; ``y`` sampled outputs (with noise) (N, p); ``r`` references (N, q); ``s`` external scheduling
    signals (N, e); ``u`` the command applied after the sample (N, m); ``sat`` the controller's saturation flags
    (N, m); ``got`` whether the command for this sample arrived in time; ``latency_ns`` send -> command (NaN when
    not got); ``tick_ns`` when the step started (realtime: the pacer's wake-up; lockstep: the send), relative to the
    run start; ``deadline_ns`` when it was due (realtime; NaN in lockstep); ``x`` the plant states (N, n_plant);
    ``flags`` the command's status flags (:mod:`gainlink.laws.flags`; 0 without a command); ``sigma`` the sigma the
    law used (NaN for a law without one; held from the step before without a command); ``nan_sent`` whether the
    sample went out as NaN (a ``nan`` fault: ``y`` is the plant's own sample); ``twin_y``, ``twin_u``, ``twin_z``
    the float64 twin's sampled outputs, commands and integrators (:mod:`gainlink.proof.twin`) (``x`` and the twin's
    are NaN when the twin is off; ``twin_z`` also for a law without integrators); ``model_y``, ``model_u`` the
    model twin's (:mod:`.model_twin`; None when it is off).
    """

    t: np.ndarray
    y: np.ndarray
    r: np.ndarray
    s: np.ndarray
    u: np.ndarray
    sat: np.ndarray
    got: np.ndarray
    latency_ns: np.ndarray
    tick_ns: np.ndarray
    deadline_ns: np.ndarray
    x: np.ndarray
    flags: np.ndarray
    sigma: np.ndarray
    nan_sent: np.ndarray
    twin_y: np.ndarray
    twin_u: np.ndarray
    twin_z: np.ndarray
    model_y: np.ndarray | None = None
    model_u: np.ndarray | None = None

    @property
    def has_twin(self) -> bool:
        """True when the run had a twin (its columns are finite)."""
        return bool(self.t.size) and bool(np.all(np.isfinite(self.twin_u)))

    @property
    def has_model_twin(self) -> bool:
        """True when the run had a model twin (:mod:`.model_twin`)."""
        return self.model_u is not None and bool(self.t.size) and bool(np.all(np.isfinite(self.model_u)))


def column_max(a: np.ndarray) -> list[float]:
    """Each column's largest value of ``a`` (N, k) (NaN when it holds one), one column at a time: numpy reduces
    along axis 0 of a (1000, 2) array at ~4x the cost of two one-column reductions, and a maximum does not depend
    on the order it is taken in."""
    return [float(a[:, i].max()) for i in range(a.shape[1])]


def _pct(values: np.ndarray) -> dict:
    v = values[np.isfinite(values)]
    if v.size == 0:
        return {"p50": None, "p99": None, "max": None}
    return {"p50": float(np.percentile(v, 50)), "p99": float(np.percentile(v, 99)), "max": float(v.max())}


def tracking(t: np.ndarray, y: np.ndarray, r: np.ndarray, *, band: float = 0.02) -> dict:
    """Overshoot (% of the last reference change, or of the initial error), settling time and IAE.

    The error is ``e = r - y``. The reference's last change (or t = 0) starts the response; its
    size ``e0`` is the error just after it. Overshoot is how far ``e`` crosses zero the other way,
    as a percentage of ``|e0|``; settling time is when ``|e|`` last leaves ``band * |e0|``
    (NaN when it never settles); IAE integrates ``|e|`` over the whole run.
    """
    dt = float(t[1] - t[0]) if t.size > 1 else 0.0
    e = r - y
    changes = np.flatnonzero(np.abs(np.diff(r)) > 0)
    k0 = int(changes[-1] + 1) if changes.size else 0
    e0 = float(e[k0])
    iae = float(np.sum(np.abs(e)) * dt)
    seg = e[k0:] * (np.sign(e0) if e0 != 0 else 1.0)
    scale = abs(e0)
    if scale < 1e-12:  # regulation: no initial error, measure against the largest excursion instead
        scale = float(np.abs(seg).max())
        overshoot = None
        if scale < 1e-12:
            return {"overshoot_pct": None, "settling_time_s": 0.0, "iae": iae, "start_s": float(t[k0])}
    else:
        overshoot = float(max(0.0, -seg.min()) / scale * 100.0)
    outside = np.flatnonzero(np.abs(seg) > band * scale)
    if outside.size == 0:
        settle = 0.0
    elif outside[-1] == seg.size - 1:
        settle = float("nan")
    else:
        settle = float(t[k0 + outside[-1] + 1] - t[k0])
    return {"overshoot_pct": overshoot, "settling_time_s": settle, "iae": iae, "start_s": float(t[k0])}


def timing(latency_ns: np.ndarray, tick_ns: np.ndarray, deadline_ns: np.ndarray, *, mode: str) -> dict:
    """``latency_us`` and ``period_jitter_us`` (p50, p99, max) of a run's steps: in real time the jitter is each
    tick's distance from its deadline, otherwise each period's from the median period."""
    if mode == "realtime":
        jitter_us = np.abs(tick_ns - deadline_ns) / 1e3
    else:
        period = np.diff(tick_ns) / 1e3
        jitter_us = np.abs(period - np.median(period)) if period.size else np.zeros(0)
    return {"latency_us": _pct(latency_ns / 1e3), "period_jitter_us": _pct(jitter_us)}


def compute_metrics(
    trace: RunTrace,
    *,
    artifact: Any,
    mode: str,
    late: int,
    period_s: float,
    model_start: str = "",
    timed: dict | None = None,
) -> dict:
    """The report's metrics from a trace (JSON-able dict; NaN becomes ``None``); ``model_start`` says where the
    model twin started; ``timed``: :func:`timing` of the trace when the caller has it already (a campaign block's
    runs share their calls' timing). The law's own blocks (:meth:`gainlink.laws.Law.run_report`) are the caller's."""
    a = artifact
    N = trace.t.size
    lost = int(np.count_nonzero(~trace.got))
    if timed is None:
        timed = timing(trace.latency_ns, trace.tick_ns, trace.deadline_ns, mode=mode)
    sig = a.signals
    sat_frac = trace.sat.mean(axis=0) if N else np.zeros(a.m)
    out = {
        "steps": N,
        "lost": lost,
        "late": int(late),
        "deadline_misses": lost,
        "latency_us": timed["latency_us"],
        "period_jitter_us": timed["period_jitter_us"],
        "period_s": period_s,
        "saturation_fraction": {name: float(v) for name, v in zip(sig["inputs"], sat_frac)},
        # steps in which any input saturated (at most ``steps``), and per input (these may add up to more)
        "saturated_steps": int(np.count_nonzero(trace.sat.any(axis=1))) if N else 0,
        "saturated_steps_per_input": {
            name: int(v) for name, v in zip(sig["inputs"], trace.sat.sum(axis=0) if N else np.zeros(a.m))
        },
        "outputs_final": {name: float(v) for name, v in zip(sig["outputs"], trace.y[-1])} if N else {},
        "inputs_peak_abs": dict(zip(sig["inputs"], column_max(np.abs(trace.u)))) if N else {},
        "outputs_peak_abs": dict(zip(sig["outputs"], column_max(np.abs(trace.y)))) if N else {},
        "refused_steps": int(np.count_nonzero(trace.flags & flags.FAULT)),  # answered with the fault flag
    }
    if trace.has_twin:
        if a.q and np.all(np.isfinite(trace.twin_z)):  # the controller's state is not on the link: the twin's
            out["peak_integrator"] = {
                name: float(v) for name, v in zip(sig["references"], np.abs(trace.twin_z).max(axis=0))
            }
            integral_cmd = np.abs(trace.twin_z @ a.Ki.T).max(axis=0)
            out["peak_integral_command"] = {name: float(v) for name, v in zip(sig["inputs"], integral_cmd)}
        out["twin"] = twin_comparison(
            t=trace.t, y=trace.y, u=trace.u, r=trace.r, twin_y=trace.twin_y, twin_u=trace.twin_u, artifact=a
        ).to_dict()
    if trace.has_model_twin:
        out["model_twin"] = model_mismatch(
            t=trace.t, y=trace.y, r=trace.r, model_y=trace.model_y, artifact=a, start=model_start
        ).to_dict()
    tracked = {}
    if N:
        if a.q:
            for j, name in enumerate(sig["references"]):
                yj = trace.y @ a.Ci[j]
                tracked[name] = tracking(trace.t, yj, trace.r[:, j])
        else:  # a regulator: its set point is the operating point
            for i, name in enumerate(sig["outputs"]):
                tracked[name] = tracking(trace.t, trace.y[:, i], np.full(N, a.y_op[i]))
    out["tracked"] = tracked
    return _clean(out)


def link_capacity(sent_ns: np.ndarray, back_ns: np.ndarray, *, answered_in_time: np.ndarray) -> dict:
    """What the link and the controller sustained: the service time of every answered sample.

    Parameters
    ----------
    sent_ns, back_ns : ndarray
        Per step, when the sample was sent and when its command came back, in time or late (ns, NaN: never).
    answered_in_time : ndarray of bool
        Per step, whether the command came back before the step's deadline.

    Returns
    -------
    dict
        ``service_us`` (p50, p99, max) of the service time ``back_k - max(sent_k, back_prev)``: a sample sent
        while the previous one is still being answered waits in the link, and that wait is not its service
        (in lockstep each sample waits for the previous command, so the service time is the round trip);
        ``loop_hz_p99``: the highest loop rate whose period covers the p99 service time; ``round_trips_per_s``:
        one over the mean service time (back to back); ``answered``, ``commands`` (in time), ``late_answers``
        and ``unanswered`` (sent, never answered: lost, or still in the link when the run ended).
    """
    was_sent = np.isfinite(sent_ns)
    answered = was_sent & np.isfinite(back_ns)
    counts = {
        "answered": int(np.count_nonzero(answered)),
        "commands": int(np.count_nonzero(answered_in_time)),
        "late_answers": int(np.count_nonzero(answered & ~answered_in_time)),
        "unanswered": int(np.count_nonzero(was_sent & ~answered)),
    }
    if not answered.any():
        return {**counts, "service_us": _pct(np.zeros(0)), "round_trips_per_s": None, "loop_hz_p99": None}
    order = np.argsort(back_ns[answered], kind="stable")
    back, sent = back_ns[answered][order], sent_ns[answered][order]
    previous = np.concatenate([[-np.inf], back[:-1]])
    service = back - np.maximum(sent, previous)
    return {
        **counts,
        "service_us": _pct(service / 1e3),
        "round_trips_per_s": float(1e9 / service.mean()),
        "loop_hz_p99": float(1e9 / np.percentile(service, 99)),
    }


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, float) and not math.isfinite(obj):  # numpy's isfinite costs ~1 us a call on a float
        return None
    return obj
