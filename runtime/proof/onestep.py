"""The one-step (resynchronised) check: an engine's every step against the float64 law from the same state.

Replaying recorded samples open loop through a float32 and a float64 implementation of an unstable
compensator amplifies rounding like ``|z|^k`` (see :mod:`gainlink.synthesis.compensator`), so two correct
implementations "disagree" after a few dozen steps. Here, before each step ``k`` the float64 law
(:class:`~gainlink.proof.reference.ReferenceLoop`) is put into the engine's own state after step ``k - 1``
(``xh``, ``z``; the artifact's initial state for step 0), runs step ``k`` on the same ``y`` and ``r``, and its
command ``u``, saturation flags, fault flag and next state ``xh``, ``z`` must match the engine's within a
float32 bound computed from the magnitudes in that step. This is valid whatever the compensator.

The bound (``EPS = 2**-24``, float32's unit roundoff). The C computes each output as a chain of ``T``
fused multiply-adds ``s = sum_t c_t x_t`` over float32 coefficients ``c_t`` (derived in double from the
float32 gain set and rounded once) and float32 operands ``x_t`` (its state, ``y`` and ``r`` rounded to
float32, the command). Against the float64 law from the same state, to first order in ``EPS``:

- the accumulation contributes at most ``T EPS sum_t |c_t x_t|``;
- a coefficient built from up to three rounded gains (``Ad - (Ad M) Cd``, ``K - (K M) Cd``) is off by at
  most ``4 EPS a_t``, where ``a_t`` is the same formula in absolute values (``|Ad| + |Ad||M||Cd|``, ...);
- ``y`` and ``r`` rounded to float32 are off by ``EPS |y|``, ``EPS |r|``; an operand that is itself a
  result of the step (``u`` in the estimate update, ``u - v`` in back-calculation) carries its own bound,
  multiplied by its coefficient's magnitude.

With ``mu = sum_t a_t |x_t|`` (the magnitudes in that step) the bound is ``2 EPS (T + 5) mu`` plus the
propagated operand bounds: twice the first-order worst case, so higher-order terms and the float32
limits (``EPS |u|`` on a clamped command) are covered. The magnitudes per quantity:

====================  ============================================================================
``v`` (predictor)     ``|u_op| + |K||xh| + |Ki||z|``, T = n + q + 1
``v`` (current)       ``|u_op| + (|K| + |K||M||Cd|)|xh| + |K||M|(|y| + |y_op|) + |Ki||z|``, T = n + p + q + 1
``z``                 ``|z| + Ts (|r| + |Ci||y|) + |Kaw||u - v|``, T = p + 2 + 2m; plus ``|Kaw|`` (bound of u + v)
``xh`` (predictor)    ``(|Ad| + |L||Cd|)|xh| + (|Bd| + |L||Dd|)(|u| + |u_op|) + |L|(|y| + |y_op|)``,
                      T = n + m + p; plus ``|Bd - L Dd|`` times the bound of ``u``
``xh`` (current)      ``(|Ad| + |Ad||M||Cd|)|xh| + |Bd|(|u| + |u_op|) + |Ad||M|(|y| + |y_op|)``; same T
====================  ============================================================================

Saturation flags may differ only where the law's unsaturated command lies within its bound of a limit;
with ``anti_windup = "clamp"`` the integrator may then have held or integrated, so its bound widens by
``Ts |r - Ci y|`` on that step. A refused (non-finite) sample must be refused by both, with the safe
command and the state unchanged.

What it catches (tests/test_onestep.py). On correct host builds, over the examples' golden records and
twelve random closed-loop records, the largest error stays below 15 % of the bound. The bound counts
every term by its magnitude, so how small a wrong gain it catches depends on that gain's share of a
step's magnitudes: the largest entry of one gain matrix bent by 1e-4 relative in the C's gain set is
caught for every matrix of the pendulum and quadrotor_lateral records, and for ``Ad`` and ``Cd`` on all of
them; not always for the other matrices (missed, for instance, for ``K`` on one random record and for
Wood-Berry's small back-calculation gain ``Kaw``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from ..shipping.artifact import Artifact
from .reference import ReferenceLoop, Trace

EPS = 2.0**-24
SLACK = 2.0  # times the first-order worst case
EXTRA_TERMS = 5  # coefficient (4 EPS) and operand (1 EPS) rounding, in units of T


@dataclass(frozen=True)
class StepMismatch:
    """The first quantity of a step that broke its bound."""

    step: int
    quantity: str  # "u0", "sat1", "xh3", "z0", "fault"
    got: float
    expected: float
    bound: float

    def describe(self, engine: str = "the engine") -> str:
        """One line naming the step and the quantity."""
        if self.quantity.startswith("sat") or self.quantity == "fault":
            return (
                f"step {self.step}: {self.quantity} of {engine} is {int(self.got)} where the float64 law from "
                f"its own state gives {int(self.expected)}"
            )
        return (
            f"step {self.step}: {self.quantity} of {engine} is {self.got:.9g} where the float64 law from its "
            f"own state gives {self.expected:.9g} (difference {abs(self.got - self.expected):.3g} > float32 "
            f"bound {self.bound:.3g})"
        )


@dataclass(frozen=True)
class OneStepCheck:
    """The outcome of :func:`one_step_check`.

    ``worst`` maps ``u``, ``xh``, ``z`` to the largest error / bound over all steps (1 is the bound);
    ``max_rel_u`` is the largest command error relative to each input's limit span.
    """

    steps: int
    failures: int
    first_failure: StepMismatch | None
    worst: dict = field(default_factory=dict)
    max_rel_u: float = 0.0

    @property
    def passed(self) -> bool:
        """True when every step stayed within its bound."""
        return self.failures == 0

    def summary(self) -> str:
        """One line: pass/fail and how close to the bound the engine came."""
        worst = ", ".join(f"{k} {v:.3g}" for k, v in self.worst.items())
        head = "pass" if self.passed else f"FAIL on {self.failures} step(s)"
        return (
            f"{head}, {self.steps} steps; largest error / float32 bound: {worst}; "
            f"max |du| {self.max_rel_u:.3g} of the limit span"
        )


@dataclass(frozen=True)
class _Bounds:
    u: np.ndarray  # (m,)
    v: np.ndarray
    xh: np.ndarray  # (n,)
    z: np.ndarray  # (q,)


class _Magnitudes:
    """Absolute-value forms of the coefficient formulas of one artifact (see the module docstring)."""

    def __init__(self, a: Artifact) -> None:
        ab = np.abs
        self.a = a
        self.u_op = ab(a.u_op)
        self.y_op = ab(a.y_op)
        self.Ki, self.Kaw, self.Ci = ab(a.Ki), ab(a.Kaw), ab(a.Ci)
        if a.observer_form == "current":
            KM = ab(a.K) @ ab(a.M)
            AM = ab(a.Ad) @ ab(a.M)
            self.Kx, self.Ky = ab(a.K) + KM @ ab(a.Cd), KM
            self.F, self.G, self.L = ab(a.Ad) + AM @ ab(a.Cd), ab(a.Bd), AM
            self.G_exact = ab(a.Bd)
            self.Tv = a.n + a.p + a.q + 1
        else:
            self.Kx, self.Ky = ab(a.K), np.zeros((a.m, a.p))
            self.F, self.G, self.L = ab(a.Ad) + ab(a.L) @ ab(a.Cd), ab(a.Bd) + ab(a.L) @ ab(a.Dd), ab(a.L)
            self.G_exact = ab(a.Bd - a.L @ a.Dd)
            self.Tv = a.n + a.q + 1
        self.Tz = a.p + 2 + 2 * a.m
        self.Tx = a.n + a.m + a.p

    def bounds(self, *, xh, z, y, r, u, v, sat_differs: bool) -> _Bounds:
        a = self.a
        g = lambda T: SLACK * EPS * (T + EXTRA_TERMS)  # noqa: E731
        ay, ar = np.abs(y), np.abs(r)
        mu_v = self.u_op + self.Kx @ np.abs(xh) + self.Ky @ (ay + self.y_op) + self.Ki @ np.abs(z)
        bv = g(self.Tv) * mu_v
        bu = bv + SLACK * EPS * np.abs(u)
        mu_z = np.abs(z) + a.Ts * (ar + self.Ci @ ay)
        bz = np.zeros(a.q)
        if a.q:
            if a.anti_windup == "backcalc":
                mu_z = mu_z + self.Kaw @ np.abs(u - v)
                bz = self.Kaw @ (bu + bv)
            bz = bz + g(self.Tz) * mu_z
            if sat_differs and a.anti_windup == "clamp":
                bz = bz + a.Ts * np.abs(r - a.Ci @ y) * (1 + SLACK * EPS * self.Tz)
        mu_x = self.F @ np.abs(xh) + self.G @ (np.abs(u) + self.u_op) + self.L @ (ay + self.y_op)
        bx = g(self.Tx) * mu_x + self.G_exact @ bu
        return _Bounds(u=bu, v=bv, xh=bx, z=bz)


def one_step_check(artifact: Artifact, Y: np.ndarray, R: np.ndarray, trace: Trace) -> OneStepCheck:
    """Check every step of ``trace`` against the float64 law started from the trace's own state.

    Parameters
    ----------
    artifact : Artifact
        The artifact the engine ran.
    Y, R : ndarray
        The samples it was fed, (N, p) and (N, q) (``R`` may be None without integral action), as
        float64 (non-finite values allowed).
    trace : Trace
        What the engine returned: command, flags and state after each step.

    Returns
    -------
    OneStepCheck
        Failures (with the first one named), the largest error relative to its bound per quantity, and
        the largest command error relative to the limit span.

    Raises
    ------
    DataError
        ``trace`` does not hold one step per sample.

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> art = gl.design(ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01), Q=[[1.0]], R=[[1.0]],
    ...                 W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    >>> from gainlink.laws.lq.model import Float32Loop
    >>> Y = np.linspace(0.0, 20.0, 50).reshape(-1, 1)
    >>> check = one_step_check(art, Y, None, Float32Loop(art).run(Y))  # the C's arithmetic
    >>> check.passed, check.worst["u"] < 0.5
    (True, True)
    """
    a = artifact
    Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
    N = Y.shape[0]
    R = np.zeros((N, a.q)) if R is None or a.q == 0 else np.asarray(R, dtype=float).reshape(N, a.q)
    if trace.u.shape[0] != N:
        raise DataError(f"the trace has {trace.u.shape[0]} steps, the samples {N}")
    mags = _Magnitudes(a)
    law = ReferenceLoop(a)
    span = np.where(a.u_max > a.u_min, a.u_max - a.u_min, 1.0)
    worst = {"u": 0.0, "xh": 0.0, "z": 0.0}
    max_rel_u = 0.0
    failures, first = 0, None
    xh_prev, z_prev = a.xh0.copy(), a.z0.copy()
    for k in range(N):
        law.xh, law.z = xh_prev.copy(), z_prev.copy()
        res = law.step(Y[k], R[k])
        bad = _compare_step(k, a, mags, res, law, xh_prev, z_prev, Y[k], R[k], trace, worst)
        max_rel_u = max(max_rel_u, float(np.max(np.abs(trace.u[k] - res.u) / span)))
        if bad is not None:
            failures += 1
            first = first or bad
        xh_prev, z_prev = trace.xh[k], trace.z[k]
    return OneStepCheck(steps=N, failures=failures, first_failure=first, worst=worst, max_rel_u=max_rel_u)


def _compare_step(k, a, mags, res, law, xh_prev, z_prev, y, r, trace, worst) -> StepMismatch | None:
    if bool(trace.fault[k]) != res.fault:
        return StepMismatch(k, "fault", float(trace.fault[k]), float(res.fault), 0.0)
    if res.fault:  # the safe command, the state untouched
        b = _Bounds(u=SLACK * EPS * np.abs(res.u), v=np.zeros(a.m), xh=np.zeros(a.n), z=np.zeros(a.q))
        return _first_over(k, worst, b, res, law, trace)
    near = np.minimum(np.abs(res.v - a.u_min), np.abs(res.v - a.u_max))
    b0 = mags.bounds(xh=xh_prev, z=z_prev, y=y, r=r, u=res.u, v=res.v, sat_differs=False)
    may_differ = near <= b0.v + SLACK * EPS * np.maximum(np.abs(a.u_min), np.abs(a.u_max))
    differs = trace.saturated[k] != res.saturated
    for i in np.flatnonzero(differs & ~may_differ):
        return StepMismatch(k, f"sat{i}", float(trace.saturated[k][i]), float(res.saturated[i]), 0.0)
    b = mags.bounds(xh=xh_prev, z=z_prev, y=y, r=r, u=res.u, v=res.v, sat_differs=bool(differs.any()))
    return _first_over(k, worst, b, res, law, trace)


def _first_over(k, worst, b: _Bounds, res, law, trace) -> StepMismatch | None:
    found = None
    for name, got, want, bound in (
        ("u", trace.u[k], res.u, b.u),
        ("xh", trace.xh[k], law.xh, b.xh),
        ("z", trace.z[k], law.z, b.z),
    ):
        if want.size == 0:
            continue
        err = np.abs(got - want)
        tiny = np.finfo(float).tiny
        ratio = err / np.maximum(bound, tiny)
        ratio = np.where(err == 0.0, 0.0, ratio)
        ratio = np.where(np.isfinite(ratio), ratio, np.inf)
        worst[name] = max(worst[name], float(np.max(ratio)))
        over = np.flatnonzero(~(ratio <= 1.0))
        if over.size and found is None:
            i = int(over[0])
            found = StepMismatch(k, f"{name}{i}", float(got[i]), float(want[i]), float(bound[i]))
    return found
