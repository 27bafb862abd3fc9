"""The float64 reference of the scheduled law (docs/design.md, scheduled law): the velocity form on coefficients
interpolated linearly in sigma. The C loop, its float32 model and every test of a schema-2 artifact compare
against this.

The law, one step (given the absolute measurement ``y`` (p), reference ``r`` (q) and external scheduling signals
``s`` (e); ``a`` is the artifact, ``S = a.schedule`` its points ``S1 < ... < SN``)::

    # 1. refusal: a non-finite y or r changes nothing (sigma, its filter, delta, u_prev, y_prev, e_prev,
    #    started all stay) and returns the safe command clamp(u_op(sigma_held), u_min, u_max) with the fault flag.
    # 2. sigma (raw = y[index] when sigma is an output, s[index] when external):
    if raw is not finite: sigma = sigma_held                          # flag HELD (no filter, no rate limit;
                                                                      #   before any valid sigma: S1)
    else:
        c = clip(raw, S1, SN)                                         # flag CLIPPED when c != raw
        if not started: sigma_f = c;  sigma = c                       # the first valid sample starts there
        else:
            sigma_f = sigma_f + alpha (c - sigma_f)                   # alpha = 1 - exp(-Ts / filter_tau);
                                                                      #   no filter (alpha = 1): sigma_f = c
            d = sigma_f - sigma_held                                  # rate limit (none: rate_max null)
            sigma = sigma_f if |d| <= Ts rate_max else sigma_held + sign(d) Ts rate_max   # flag RATE
    sigma_held = sigma
    # 3. coefficients: i with Si <= sigma <= Si+1 (the last interval at SN), lam = (sigma - Si) / (Si+1 - Si),
    #    X = X_i + lam (X_i+1 - X_i) for X in Kx Ky Kz F G Ly (and u_op, only to start and for the safe command)
    # 4. start: the first valid step after a reset sets y_prev = y, u_prev = clamp(u_op(sigma)), e_prev = 0,
    #    delta = 0, so it does not kick.
    dy  = y - y_prev
    du  = -Kx delta - Ky dy - Kz e_prev                               # Kz = Ts Ki
    v   = u_prev + du                                                 # unsaturated command
    u   = clamp(v, u_min, u_max)                                      # saturation flags: u != v
    delta  = F delta + G (u - u_prev) + Ly dy                          # the observer sees the applied increment
    e_prev = r - Ci y;  y_prev = y;  u_prev = u                        # u_prev holds the saturated command

``delta`` is the estimate's increment ``xh[k] - xh[k-1]``; ``u_prev`` integrates the command (so the law holds no
trim: ``u_op``, ``y_op`` only start it, and the saturated ``u_prev`` is its anti-windup); ``Kz e_prev`` is the
integrator's increment. At a fixed sigma and unsaturated this is the positional law of the coefficients there,
differenced: its loop has the frozen design's eigenvalues plus ``m + p`` at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...shipping.artifact import Artifact
from .block import interval, lerp

SIGMA_HELD, SIGMA_CLIPPED, SIGMA_RATE = 1, 2, 4  # the sigma flags of a step (bits)


@dataclass(frozen=True)
class ScheduledStep:
    """One step's command, saturation flags, refusal flag, unsaturated command, sigma used and its flags."""

    u: np.ndarray
    saturated: np.ndarray
    fault: bool
    v: np.ndarray
    sigma: float
    sigma_flags: int


@dataclass
class ScheduledState:
    """The law's whole state (what a one-step check resynchronises): see the module docstring."""

    delta: np.ndarray
    u_prev: np.ndarray
    y_prev: np.ndarray
    e_prev: np.ndarray
    sigma: float
    sigma_f: float
    started: bool

    def copy(self) -> ScheduledState:
        """A deep copy."""
        return ScheduledState(self.delta.copy(), self.u_prev.copy(), self.y_prev.copy(), self.e_prev.copy(),
                              self.sigma, self.sigma_f, self.started)  # fmt: skip

    def vector(self) -> np.ndarray:
        """The state as one vector ``[delta, u_prev, y_prev, e_prev, sigma, sigma_f, started]``."""
        return np.concatenate([self.delta, self.u_prev, self.y_prev, self.e_prev,
                               [self.sigma, self.sigma_f, float(self.started)]])  # fmt: skip


@dataclass(frozen=True)
class ScheduledTrace:
    """A block of steps: commands, flags, the sigma used, and the state after each step (rows of
    :meth:`ScheduledState.vector`). ``numeric`` is the arithmetic a trace read from a file names (``float64``: the
    float64 law's, ``float32``: the C's; None: a file that names none, or a trace not read from a file)."""

    u: np.ndarray
    saturated: np.ndarray
    fault: np.ndarray
    sigma: np.ndarray
    sigma_flags: np.ndarray
    state: np.ndarray
    numeric: str | None = None


class ScheduledLoop:
    """The scheduled law in float64 (module docstring), with its state in :attr:`state`.

    Parameters
    ----------
    artifact : Artifact
        A scheduled (schema-2) artifact.
    """

    def __init__(self, artifact: Artifact) -> None:
        if artifact.schedule is None:
            raise ValueError(f"artifact {artifact.name} is not scheduled: use gainlink.proof.reference")
        self.a = artifact
        self.S = artifact.schedule
        self.reset()

    def reset(self) -> None:
        """Back to the start: zero increments, sigma at the first point, not started (the first valid sample
        starts the law where it is)."""
        a, S = self.a, self.S
        sigma0 = float(S.points[0])
        self.state = ScheduledState(np.zeros(a.n), self._trim(sigma0), np.zeros(a.p), np.zeros(a.q), sigma0, sigma0,
                                    False)  # fmt: skip

    def _trim(self, sigma: float) -> np.ndarray:
        i, lam = interval(self.S.points, sigma)
        return np.minimum(np.maximum(lerp(self.S.u_op, i, lam), self.a.u_min), self.a.u_max)

    def safe_command(self) -> np.ndarray:
        """The command on a refused sample: ``u_op`` at the held sigma, clamped into the limits."""
        return self._trim(self.state.sigma)

    def step(self, y, r=None, s=None) -> ScheduledStep:
        """One sample on the absolute ``y`` (p), reference ``r`` (q) and external scheduling signals ``s``."""
        a = self.a
        y = np.asarray(y, dtype=float).reshape(a.p)
        r = np.zeros(a.q) if r is None else np.asarray(r, dtype=float).reshape(a.q)
        s = np.zeros(len(self.S.external)) if s is None else np.asarray(s, dtype=float).reshape(len(self.S.external))
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(r))):
            u = self.safe_command()
            return ScheduledStep(u, np.zeros(a.m, dtype=bool), True, u.copy(), self.state.sigma, 0)
        sigma, flags = self._sigma(y[self.S.index] if self.S.source == "output" else s[self.S.index])
        i, lam = interval(self.S.points, sigma)
        c = {k: lerp(v, i, lam) for k, v in self.S.coef.items()}
        st = self.state
        if not st.started:
            st.y_prev, st.u_prev, st.e_prev, st.delta = y.copy(), self._trim(sigma), np.zeros(a.q), np.zeros(a.n)
            st.started = True
        dy = y - st.y_prev
        du = -c["Kx"] @ st.delta - c["Ky"] @ dy - c["Kz"] @ st.e_prev
        v = st.u_prev + du
        u = np.minimum(np.maximum(v, a.u_min), a.u_max)
        st.delta = c["F"] @ st.delta + c["G"] @ (u - st.u_prev) + c["Ly"] @ dy
        st.e_prev, st.y_prev, st.u_prev = r - a.Ci @ y, y.copy(), u
        return ScheduledStep(u, u != v, False, v, sigma, flags)

    def _sigma(self, raw: float) -> tuple[float, int]:
        """Hold, clip, filter and rate-limit sigma (module docstring, step 2); updates the state."""
        st, S = self.state, self.S
        if not np.isfinite(raw):
            return st.sigma, SIGMA_HELD
        c = S.clip(float(raw))
        flags = SIGMA_CLIPPED if c != raw else 0
        if not st.started:
            st.sigma_f = st.sigma = c
            return c, flags
        st.sigma_f = c if S.filter_alpha == 1.0 else st.sigma_f + S.filter_alpha * (c - st.sigma_f)
        change = st.sigma_f - st.sigma
        limit = np.inf if S.rate_max is None else self.a.Ts * S.rate_max
        if abs(change) > limit:
            st.sigma, flags = st.sigma + (limit if change > 0 else -limit), flags | SIGMA_RATE
        else:
            st.sigma = st.sigma_f
        return st.sigma, flags

    def run(self, Y, R=None, Sx=None) -> ScheduledTrace:
        """One step per row of ``Y`` (N, p), ``R`` (N, q) and ``Sx`` (N, e) from the current state."""
        a = self.a
        Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
        N, e = Y.shape[0], len(self.S.external)
        R = np.zeros((N, a.q)) if R is None else np.asarray(R, dtype=float).reshape(N, a.q)
        Sx = np.zeros((N, e)) if Sx is None else np.asarray(Sx, dtype=float).reshape(N, e)
        steps, states = [], []
        for k in range(N):
            steps.append(self.step(Y[k], R[k], Sx[k]))
            states.append(self.state.vector())
        return ScheduledTrace(
            u=np.array([st.u for st in steps]).reshape(N, a.m),
            saturated=np.array([st.saturated for st in steps], dtype=bool).reshape(N, a.m),
            fault=np.array([st.fault for st in steps], dtype=bool),
            sigma=np.array([st.sigma for st in steps]),
            sigma_flags=np.array([st.sigma_flags for st in steps], dtype=int),
            state=np.array(states).reshape(N, -1),
        )
