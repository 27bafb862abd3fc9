"""The compensator on its own: the controller from (y, r) to the unsaturated command, and its stability.

A controller designed for an open-loop-unstable plant is often unstable by itself (an LQG compensator
has no reason to be stable). That is harmless while the loop is closed, but it changes what a user can
do with it: the controller must not be started or left running open loop, a broken sensor path lets its
state and command run away, and replaying recorded samples through two implementations of it (float32
and float64) diverges like ``|z|^k`` even when both are right (compare one step at a time instead:
:func:`gainlink.proof.replay_io.one_step_check`).

The compensator is :func:`gainlink.shipping.systems.controller_matrices`: state ``[xh; z]``, input
``[y - y_op; r - Ci y_op]``, output ``v - u_op`` (unsaturated, so back-calculation and clamping are
inactive). The integrators contribute ``q`` poles at exactly ``z = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .analysis import complex_pairs

UNSTABLE_MARGIN = 1e-9  # |z| above 1 + this is an unstable pole (integrators sit at exactly 1)


@dataclass(frozen=True)
class CompensatorStability:
    """Poles of the compensator (from y, r to u, unsaturated) and what they mean.

    ``spectral_radius`` is the largest pole magnitude including the integrators (``>= 1`` with integral
    action); ``unstable_poles`` are those with ``|z| > 1`` (integrators excluded, they sit at 1).
    """

    poles: np.ndarray
    spectral_radius: float
    unstable_poles: np.ndarray
    integrators: int

    @property
    def radius_without_integrators(self) -> float:
        """Largest pole magnitude of the estimator-feedback part (the integrators' poles at 1 left out)."""
        own = self.poles[: self.poles.size - self.integrators]
        return float(np.max(np.abs(own))) if own.size else 0.0

    def describe(self) -> str:
        """A short phrase: the largest pole and the verdict."""
        integ = f" besides {self.integrators} integrator pole(s) at z = 1" if self.integrators else ""
        verdict = "stable" if self.stable else "UNSTABLE"
        return f"compensator poles max |z| = {self.radius_without_integrators:.4g}{integ} ({verdict})"

    @property
    def stable(self) -> bool:
        """No pole outside the unit circle (integrators at z = 1 count as marginal, not unstable)."""
        return self.unstable_poles.size == 0

    def warning(self) -> str | None:
        """A plain-words warning when the compensator is unstable, else None."""
        if self.stable:
            return None
        worst = float(np.max(np.abs(self.unstable_poles)))
        return (
            f"the compensator (controller from y, r to u, unsaturated) is unstable: {self.unstable_poles.size} "
            f"pole(s) outside the unit circle, largest |z| = {worst:.4g}. The closed loop is stable, but the "
            "controller must only run with the loop closed: start it with the plant running and the sensors "
            "valid, and treat a broken sensor path (stuck or disconnected measurement) as a fault that stops "
            f"it, or its state and command run away (growing like {worst:.3g}^k per sample). Recorded samples "
            "replayed open loop through two implementations diverge for the same reason; compare them one "
            "step at a time (gainlink replay --compare)"
        )

    def to_dict(self) -> dict:
        """JSON form for the artifact's ``checks`` and reports."""
        return {
            "poles": complex_pairs(sorted(self.poles, key=lambda z: (abs(z), z.imag))),
            "spectral_radius": self.spectral_radius,
            "spectral_radius_without_integrators": self.radius_without_integrators,
            "unstable_poles": complex_pairs(self.unstable_poles),
            "stable": self.stable,
        }


def compensator_stability(artifact) -> CompensatorStability:
    """Poles and spectral radius of the compensator of a loaded :class:`~gainlink.shipping.artifact.Artifact`
    (its matrices: :func:`gainlink.shipping.systems.controller_matrices`).

    Examples
    --------
    >>> import control as ct, numpy as np, gainlink as gl
    >>> art = gl.design(ct.ss([[0.9]], [[0.1]], [[1.0]], [[0.0]], 0.01), Q=[[1.0]], R=[[1.0]],
    ...                 W=[[1e-3]], V=[[1e-4]], u_min=[-1.0], u_max=[1.0])
    >>> comp = compensator_stability(art)
    >>> comp.stable, round(comp.spectral_radius, 4) == round(float(abs(comp.poles[0])), 4)
    (True, True)
    """
    from ..shipping.systems import controller_matrices

    A, _, _, _ = controller_matrices(artifact)
    n, q = artifact.n, artifact.q
    own = np.linalg.eigvals(A[:n, :n])  # the block-triangular A: the integrators add q poles at 1
    poles = np.concatenate([own, np.ones(q, dtype=complex)])
    unstable = own[np.abs(own) > 1.0 + UNSTABLE_MARGIN]
    return CompensatorStability(
        poles=poles,
        spectral_radius=float(np.max(np.abs(poles))),
        unstable_poles=np.array(sorted(unstable, key=lambda z: (-abs(z), z.imag))),
        integrators=q,
    )
