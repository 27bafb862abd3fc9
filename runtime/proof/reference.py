"""The float64 reference of the gainlink control law (docs/design.md, "The control law").

This is the executable statement of the contract that the C loop (float32) and every test
compare against, with the operating point: samples, references, limits and commands are absolute; the estimate is a
deviation. One step is the law's products written out term by term for the artifact (:mod:`.reference_step`, where
the law is stated in order), in float64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..shipping.artifact import Artifact
from ..shipping.law_c import require_structure
from .reference_step import compile_reference_step


@dataclass(frozen=True)
class StepResult:
    """What one step returns: the command, which inputs saturated, and whether the sample was refused.

    ``v`` is the unsaturated command (equal to ``u`` on a refused sample).
    """

    u: np.ndarray
    saturated: np.ndarray
    fault: bool
    v: np.ndarray | None = None


@dataclass(frozen=True)
class Trace:
    """A block of steps: row k holds step k's command, saturation flags, and the state after it."""

    u: np.ndarray  # (N, m)
    saturated: np.ndarray  # (N, m) bool
    xh: np.ndarray  # (N, n) estimate after the step
    z: np.ndarray  # (N, q) integrator after the step
    fault: np.ndarray  # (N,) bool


class ReferenceLoop:
    """The control law in float64, with caller-visible state ``xh`` and ``z``.

    Parameters
    ----------
    artifact : Artifact
        A validated gain artifact.
    """

    def __init__(self, artifact: Artifact) -> None:
        require_structure(artifact, "lq", "ReferenceLoop")
        self.a = artifact
        self.safe_u = artifact.safe_command
        self._step = compile_reference_step(artifact)
        self.reset()

    def reset(self) -> None:
        """Put the estimate and the integrator back to the artifact's initial values."""
        self.xh = self.a.xh0.copy()
        self.z = self.a.z0.copy()

    def step(self, y: np.ndarray, r: np.ndarray | None = None) -> StepResult:
        """Run one sample of the law on the absolute measurement ``y`` (p) and reference ``r`` (q)."""
        a = self.a
        ys = np.asarray(y, dtype=float).reshape(a.p).tolist()
        rs = [0.0] * a.q if r is None else np.asarray(r, dtype=float).reshape(a.q).tolist()
        if not (all(map(math.isfinite, ys)) and all(map(math.isfinite, rs))):
            return StepResult(
                u=self.safe_u.copy(), saturated=np.zeros(a.m, dtype=bool), fault=True, v=self.safe_u.copy()
            )
        u, v, saturated, xh, z = self._step(self.xh.tolist(), self.z.tolist(), ys, rs)
        self.xh, self.z = np.array(xh), np.array(z, dtype=float)
        u, v, saturated = np.array(u), np.array(v), np.array(saturated, dtype=bool)
        return StepResult(u=u, saturated=saturated, fault=False, v=v)

    def run(self, Y: np.ndarray, R: np.ndarray | None = None) -> Trace:
        """Run one step per row of ``Y`` (N, p) and ``R`` (N, q) from the current state."""
        a = self.a
        Y = np.asarray(Y, dtype=float).reshape(-1, a.p)
        N = Y.shape[0]
        R = np.zeros((N, a.q)) if R is None else np.asarray(R, dtype=float).reshape(N, a.q)
        U = np.empty((N, a.m))
        S = np.empty((N, a.m), dtype=bool)
        XH = np.empty((N, a.n))
        Z = np.empty((N, a.q))
        F = np.empty(N, dtype=bool)
        for k in range(N):
            res = self.step(Y[k], R[k])
            U[k], S[k], F[k] = res.u, res.saturated, res.fault
            XH[k], Z[k] = self.xh, self.z
        return Trace(u=U, saturated=S, xh=XH, z=Z, fault=F)
