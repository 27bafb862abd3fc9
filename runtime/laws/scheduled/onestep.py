"""The scheduled law's one-step check with a float32 bound: each step of a trace of the C against the float64 law
started from the trace's own state, within a bound on what float32 arithmetic can change in that step.

Before step ``k`` the float64 law (:class:`~gainlink.laws.scheduled.reference.ScheduledLoop`) is put into the
trace's state after step ``k - 1`` (its reset state for step 0), runs step ``k`` on the same ``y``, ``r``, ``s``, and
the trace's command, sigma and next state must be within the bound of the float64 law's; its fault flag must be the
same, and its saturation and sigma flags the same except where the float64 law is within the bound of the
threshold that sets them. This is valid whatever the law does between steps (the unscheduled check's argument,
:mod:`gainlink.proof.onestep`), and it holds for the C itself, not only for its model.

The bound (``EPS = 2**-24``), first order in ``EPS``, from the C's operations (``gl_sched.c``, in the order
:mod:`gainlink.laws.scheduled.model` reproduces them), then doubled (``SLACK``) for higher-order terms:

- sigma. The raw value (``y`` or ``s``) is rounded to float32 (``EPS |raw|``); clipping to the float32 points moves
  it by at most ``EPS max(|raw|, |S1|, |SN|)``; the filter ``fmaf(alpha, c - sf, sf)`` passes ``alpha`` times the
  error of ``c`` and adds ``EPS (2 alpha |c - sf| + |sf'|)``; the rate limit (1-Lipschitz in ``sf``) adds
  ``EPS (|sigma| + Ts rate_max + |sf' - sigma_held|)``: the bound ``b_sigma`` on the sigma the step uses.
- each interpolated coefficient ``fmaf(lam, X[i+1] - X[i], X[i])`` of float32 tables: ``6 EPS A`` (the tables,
  the difference and the fused multiply-add, ``A`` the larger end's magnitude), plus ``slope b_sigma`` (sigma's
  error, ``slope = |X[i+1] - X[i]| / (S[i+1] - S[i])``) plus ``slope EPS (2 |S[i]| + |S[i+1]| + 3 w)`` (``lam``'s
  rounding, ``w`` the interval's width); taken over every interval sigma's error can reach.
- each sum of ``T`` products ``c x`` (a multiply then ``T - 1`` fused multiply-adds): ``T EPS sum |c x|`` plus
  each coefficient's bound times ``|x|`` plus ``|c|`` times each operand's bound (``dy = y - y_prev``:
  ``EPS (|y| + |dy|)``; the state's own values carry none, the law starts from them).
- ``v = u_prev - acc``: plus ``EPS |v|``; the clamp to the float32 limits: plus ``EPS max(|u_min|, |u_max|)``;
  ``du = u - u_prev``: plus ``EPS |du|``; ``e = r - Ci y`` (float32 ``r``, ``y``, ``Ci``): ``EPS ((p + 2) |r| + (p
  + 3) |Ci| |y|)``; ``y_prev = y``: ``EPS |y|``. On the first step after a reset ``u_prev`` is the trim at sigma
  (the coefficient bound of ``u_op``, clamped), and ``dy`` is 0 in both.

What it catches (tests/test_sched_onestep.py): on the host C's trace of a closed loop that moves sigma across the
envelope, holds, clips and rate-limits it and saturates the pump, every step is within the bound and the largest
error is a measurable fraction of it; a coefficient of the C's table bent by a relative 1e-4 is caught.
"""

from __future__ import annotations

import numpy as np

from ...errors import DataError
from ...proof.onestep import OneStepCheck, StepMismatch
from ...shipping.artifact import Artifact
from .block import interval
from .reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE, ScheduledLoop, ScheduledState

EPS = 2.0**-24
SLACK = 2.0  # times the first-order worst case


class _Bounds:
    """The float32 bounds of one step's quantities, from the artifact's tables (module docstring)."""

    def __init__(self, a: Artifact) -> None:
        S = a.schedule
        self.a, self.S = a, S
        self.points = np.asarray(S.points, dtype=float)
        self.width = np.diff(self.points)
        self.tables = dict(S.coef) | {"u_op": S.u_op[:, :, None]}
        self.limit = np.maximum(np.abs(a.u_min), np.abs(a.u_max))
        self.rate = 0.0 if S.rate_max is None else a.Ts * S.rate_max
        self.current = a.observer_form == "current"

    def sigma(self, raw: float, state: ScheduledState, sigma: float, sigma_f: float) -> tuple[float, float, float]:
        """Bounds of the sigma the step uses and of the filter's new state, and of the clipped raw value."""
        S, pts = self.S, self.points
        if not np.isfinite(raw):  # held: the last valid sigma, as it is
            return 0.0, 0.0, 0.0
        b_clip = EPS * max(abs(raw), abs(pts[0]), abs(pts[-1]))
        if not state.started:
            return b_clip, b_clip, b_clip
        alpha = S.filter_alpha
        b_sf = (
            b_clip
            if alpha == 1.0
            else alpha * b_clip + EPS * (2 * alpha * abs(S.clip(raw) - state.sigma_f) + abs(sigma_f))
        )
        b_sigma = b_sf + EPS * (abs(sigma) + self.rate + abs(sigma_f - state.sigma))
        return b_sigma, b_sf, b_clip

    def coefficient(self, name: str, sigma: float, b_sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """``(A, bound)`` of coefficient table ``name`` at sigma (its magnitude and its float32 bound)."""
        X, pts = self.tables[name], self.points
        reach = [j for j in range(self.width.size) if pts[j] <= sigma + b_sigma and pts[j + 1] >= sigma - b_sigma]
        reach = reach or [interval(pts, self.S.clip(sigma))[0]]
        A = np.max([np.maximum(np.abs(X[j]), np.abs(X[j + 1])) for j in reach], axis=0)
        slopes = [np.abs(X[j + 1] - X[j]) / self.width[j] for j in reach]
        lam = [s * EPS * (2 * abs(pts[j]) + abs(pts[j + 1]) + 3 * self.width[j]) for s, j in zip(slopes, reach)]
        return A, 6 * EPS * A + np.max(slopes, axis=0) * b_sigma + np.max(lam, axis=0)


def _sum_bound(terms: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> np.ndarray:
    """The bound of rows ``sum_t c_t x_t``: ``terms`` are ``(A, b_c, |x|, b_x)`` per block (coefficient magnitude
    and bound, operand magnitude and bound)."""
    T = sum(A.shape[1] for A, _, _, _ in terms)
    mags = sum(A @ x for A, _, x, _ in terms)
    return T * EPS * mags + sum(b @ x + A @ bx for A, b, x, bx in terms)


def step_bounds(bounds: _Bounds, state: ScheduledState, y, r, s, res, new: ScheduledState) -> dict:
    """The float32 bounds of one non-refused step of the float64 law ``res`` from ``state`` (its new state
    ``new``): ``u``, ``v``, ``sigma``, ``state`` (the state vector's), and the flags' margins."""
    a, S = bounds.a, bounds.S
    ay, ar = np.abs(np.asarray(y, float)), np.abs(np.asarray(r, float))
    raw = float(y[S.index] if S.source == "output" else s[S.index])
    b_sigma, b_sf, b_clip = bounds.sigma(raw, state, res.sigma, new.sigma_f)
    c = {k: bounds.coefficient(k, res.sigma, b_sigma) for k in ("Kx", "Ky", "Kz", "F", "G", "Ly", "u_op")}
    if state.started:
        u_prev, b_uprev = state.u_prev, np.zeros(a.m)
        dy = np.asarray(y, float) - state.y_prev
        b_dy = EPS * (ay + np.abs(dy))
        delta, e_prev = np.abs(state.delta), np.abs(state.e_prev)
    else:  # the first step: u_prev is the trim at sigma, dy and the increments are 0 in both
        u_prev = np.minimum(np.maximum(S.trim_at(res.sigma)[0], a.u_min), a.u_max)
        b_uprev = c["u_op"][1][:, 0] + EPS * bounds.limit
        dy, b_dy, delta, e_prev = np.zeros(a.p), np.zeros(a.p), np.zeros(a.n), np.zeros(a.q)
    zero_n, zero_q = np.zeros(a.n), np.zeros(a.q)
    terms = [(*c["Kx"], delta, zero_n), (*c["Kz"], e_prev, zero_q)]
    if bounds.current:
        terms.append((*c["Ky"], np.abs(dy), b_dy))
    b_v = b_uprev + _sum_bound(terms) + EPS * np.abs(res.v)
    b_u = b_v + EPS * bounds.limit
    du = res.u - u_prev
    b_du = b_u + b_uprev + EPS * np.abs(du)
    b_delta = _sum_bound([(*c["F"], delta, zero_n), (*c["G"], np.abs(du), b_du), (*c["Ly"], np.abs(dy), b_dy)])
    p = a.p
    b_e = EPS * ((p + 2) * ar + (p + 3) * (np.abs(a.Ci) @ ay))
    b_state = np.concatenate([b_delta, b_u, EPS * ay, b_e, [b_sigma, b_sf, 0.0]])
    return {"u": b_u, "v": b_v, "sigma": b_sigma, "state": b_state, "clip": b_clip, "raw": raw, "sf": new.sigma_f,
            "held": state.sigma}  # fmt: skip


def float32_bound_check(a: Artifact, Y: np.ndarray, R: np.ndarray | None, S: np.ndarray | None, trace) -> OneStepCheck:
    """Every step of ``trace`` (a scheduled replay of the C, or of its model) against the float64 law started from
    the trace's own previous state, within the float32 bound (module docstring).

    Raises
    ------
    DataError
        ``trace`` does not hold one step per sample.
    """
    Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
    N, e = Y.shape[0], len(a.schedule.external)
    R = np.zeros((N, a.q)) if R is None else np.asarray(R, dtype=float).reshape(N, a.q)
    S = np.zeros((N, e)) if S is None else np.asarray(S, dtype=float).reshape(N, e)
    if trace.u.shape[0] != N:
        raise DataError(f"the trace has {trace.u.shape[0]} steps, the samples {N}")
    law, bounds = ScheduledLoop(a), _Bounds(a)
    span = np.where(a.u_max > a.u_min, a.u_max - a.u_min, 1.0)
    worst, failures, first, max_rel_u = {"u": 0.0, "sigma": 0.0, "state": 0.0}, 0, None, 0.0
    prev = law.state.copy()
    for k in range(N):
        law.state = prev.copy()
        res = law.step(Y[k], R[k], S[k])
        bad = _compare(k, bounds, prev, (Y[k], R[k], S[k]), res, law.state, trace, worst)
        max_rel_u = max(max_rel_u, float(np.max(np.abs(trace.u[k] - res.u) / span)))
        if bad is not None:
            failures += 1
            first = first or bad
        prev = _state_from(a, trace.state[k])
    return OneStepCheck(steps=N, failures=failures, first_failure=first, worst=worst, max_rel_u=max_rel_u)


def _state_from(a: Artifact, v: np.ndarray) -> ScheduledState:
    cut = np.cumsum([a.n, a.m, a.p, a.q])
    return ScheduledState(v[: cut[0]].copy(), v[cut[0] : cut[1]].copy(), v[cut[1] : cut[2]].copy(),
                          v[cut[2] : cut[3]].copy(), float(v[-3]), float(v[-2]), bool(v[-1]))  # fmt: skip


def _compare(k, bounds: _Bounds, state, sample, res, new, trace, worst) -> StepMismatch | None:
    a = bounds.a
    if bool(trace.fault[k]) != res.fault:
        return StepMismatch(k, "fault", float(trace.fault[k]), float(res.fault), 0.0)
    if res.fault:  # the safe command (the trim at the held sigma), the state untouched
        _, b = bounds.coefficient("u_op", state.sigma, 0.0)
        zero = np.zeros(a.n + a.m + a.p + a.q + 3)
        return _first_over(k, worst, res, new, trace, b=b[:, 0] + EPS * bounds.limit, b_sigma=0.0, b_state=zero)
    b = step_bounds(bounds, state, *sample, res, new)
    bad = _flag_mismatch(k, bounds, b, res, trace)
    if bad is not None:
        return bad
    return _first_over(k, worst, res, new, trace, b=b["u"], b_sigma=b["sigma"], b_state=b["state"])


def _flag_mismatch(k, bounds: _Bounds, b: dict, res, trace) -> StepMismatch | None:
    """A saturation or sigma flag that differs where the float64 law is not within the bound of its threshold."""
    a, pts = bounds.a, bounds.points
    near_limit = np.minimum(np.abs(res.v - a.u_min), np.abs(res.v - a.u_max)) <= SLACK * b["u"]
    for i in np.flatnonzero((trace.saturated[k] != res.saturated) & ~near_limit):
        return StepMismatch(k, f"sat{i}", float(trace.saturated[k][i]), float(res.saturated[i]), 0.0)
    differs = int(trace.sigma_flags[k]) ^ int(res.sigma_flags)
    near_clip = min(abs(b["raw"] - pts[0]), abs(b["raw"] - pts[-1])) <= SLACK * b["clip"]
    change = abs(b["sf"] - b["held"])
    near_rate = abs(change - bounds.rate) <= SLACK * (b["state"][-2] + EPS * (bounds.rate + change))
    allowed = (SIGMA_CLIPPED if near_clip else 0) | (SIGMA_RATE if near_rate else 0)
    if differs & ~allowed & (SIGMA_HELD | SIGMA_CLIPPED | SIGMA_RATE):
        return StepMismatch(k, "sflags", float(trace.sigma_flags[k]), float(res.sigma_flags), 0.0)
    return None


def _first_over(k, worst, res, new, trace, *, b, b_sigma, b_state) -> StepMismatch | None:
    found = None
    for name, got, want, bound in (
        ("u", trace.u[k], res.u, SLACK * b),
        ("sigma", np.array([trace.sigma[k]]), np.array([res.sigma]), np.array([SLACK * b_sigma])),
        ("state", trace.state[k], new.vector(), SLACK * b_state),
    ):
        err = np.abs(got - want)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(err == 0.0, 0.0, err / bound)
        ratio = np.where(np.isfinite(ratio), ratio, np.inf)
        worst[name] = max(worst[name], float(np.max(ratio, initial=0.0)))
        over = np.flatnonzero(~(ratio <= 1.0))
        if over.size and found is None:
            i = int(over[0])
            found = StepMismatch(k, f"{name}{i}", float(got[i]), float(want[i]), float(bound[i]))
    return found
