"""The scheduled law (velocity form, docs/design.md "Scheduled law"): its float64 reference, the bit-exact float32
model of its C, and the host C through ctypes."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import flags
from .base import Controller, Law, Step
from .lq import sat_bits

#: The scheduled law's own sigma flags (proof.scheduled_reference) as the status flags.
_SIGMA_FLAGS = ((1, flags.SIGMA_HELD), (2, flags.SIGMA_CLIPPED), (4, flags.SIGMA_RATE))


def status_flags(sigma_flags: int, *, fault: bool) -> int:
    """The status flags of a scheduled step: its sigma flags, and FAULT for a refused sample."""
    return (flags.FAULT if fault else 0) | sum(bit for own, bit in _SIGMA_FLAGS if sigma_flags & own)


class ScheduledPython:
    """A Python scheduled law (``step(y, r, s) -> ScheduledStep``) as a :class:`Controller`."""

    def __init__(self, loop: Any, describe: dict) -> None:
        self.loop, self.describe = loop, describe

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample with its external scheduling signals."""
        res = self.loop.step(y, r, s)
        return Step(u=np.asarray(res.u, dtype=float), flags=status_flags(res.sigma_flags, fault=res.fault),
                    sat=0 if res.fault else sat_bits(res.saturated), sigma=float(res.sigma))  # fmt: skip

    def reset(self) -> None:
        """Back to the start state."""
        self.loop.reset()


class ScheduledNative:
    """The host C's ``gl_sched_t`` (:class:`~gainlink.engines.sched_native.NativeScheduledLoop`) as a
    :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from ..engines.sched_native import NativeScheduledLoop

        self.loop = NativeScheduledLoop(artifact, library=library)
        self.describe = {"kind": "firmware (host scheduled C loop, ctypes)", "library": str(self.loop.library)}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample through ``gl_sched_step``: its record's flags are the status flags (the one table)."""
        rec = self.loop.host.step(y, r, s if s.size else None)
        return Step(u=rec["u"].astype(float), flags=int(rec["flags"]), sat=int(rec["sat"]),
                    sigma=float(rec["sigma"]))  # fmt: skip

    def reset(self) -> None:
        """``gl_sched_reset``."""
        self.loop.reset()


class ScheduledLaw(Law):
    """The velocity-form law scheduled on sigma, interpolating the per-point coefficients."""

    structure = "scheduled"
    numerics = ("float32",)

    @property
    def label(self) -> str:
        return "scheduled-float32"

    def reference(self, artifact: Any) -> Controller:
        from ..proof.scheduled_reference import ScheduledLoop

        return ScheduledPython(ScheduledLoop(artifact), {"kind": "reference (float64 scheduled law)"})

    def model(self, artifact: Any) -> Controller:
        from ..proof.scheduled_float32 import ScheduledFloat32Loop

        return ScheduledPython(ScheduledFloat32Loop(artifact), {"kind": "model (the scheduled C's float32 arithmetic)"})

    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        return ScheduledNative(artifact, library=library)

    def safe_command(self, artifact: Any) -> np.ndarray:
        s = artifact.schedule
        u_op = s.trim_at(s.points[0])[0]
        return np.minimum(np.maximum(u_op, artifact.u_min), artifact.u_max)

    def r_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        s = artifact.schedule
        return artifact.Ci @ s.trim_at(s.clip(s.points[0] if sigma is None else sigma))[1]

    def externals(self, artifact: Any) -> tuple[str, ...]:
        return tuple(artifact.schedule.external)
