"""The scheduled law (velocity form, docs/design.md "Scheduled law"): its float64 reference, the bit-exact float32
model of its C, and the host C through ctypes."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from . import flags
from .base import Capabilities, Controller, Law, Step
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

    def state(self) -> np.ndarray:
        """The law's state vector (``ScheduledState.vector``: increments, previous command, sample and error,
        sigma, its filter, started)."""
        return self.loop.state.vector()


class ScheduledNative:
    """The host C's ``gl_sched_t`` (:class:`~gainlink.engines.sched_native.NativeScheduledLoop`) as a
    :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from ..engines.sched_native import NativeScheduledLoop

        self.loop = NativeScheduledLoop(artifact, library=library)
        self.sigma_at = artifact.n + artifact.m + artifact.p + artifact.q  # sigma in the state vector
        self.describe = {"kind": "firmware (host scheduled C loop, ctypes)", "library": str(self.loop.library)}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample through ``gl_sched_step``."""
        raw = self.loop.run_raw(y[None, :], r[None, :], s[None, :] if s.size else None)
        fault = int(raw["status"][0]) == -2  # GL_SCHED_ERR_NANINF
        return Step(u=raw["u"][0].astype(float), flags=status_flags(int(raw["sflags"][0]), fault=fault),
                    sat=int(raw["sat"][0]), sigma=float(raw["state"][0, self.sigma_at]))  # fmt: skip

    def reset(self) -> None:
        """``gl_sched_reset``."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """``gl_sched_state``: the C loop's state vector."""
        return self.loop.state().astype(float)


#: What the scheduled law cannot do yet, and why (each one generated line: ``Law.refuse``).
CANNOT = {
    "firmware_run": "the host build has no stdin/stdout loop executable for it yet (its CAN and MAVLink nodes run it: "
    "gainlink firmware run --can|--mavlink)",
    "fidelity": "the design-time float32 fidelity check is not written for the velocity form yet (its one-step check "
    "and the closed-loop twin are)",
    "fuzz": "no fuzz harness builds on its tables yet",
    "one_step": "its one-step check against the float64 law has no float32 bound yet (the C is checked bit for bit "
    "against its float32 model: gainlink replay --engine native --compare)",
}


class ScheduledLaw(Law):
    """The velocity-form law scheduled on sigma, interpolating the per-point coefficients."""

    structure = "scheduled"
    numerics = ("float32",)

    @property
    def label(self) -> str:
        return "scheduled-float32"

    @property
    def capabilities(self) -> Capabilities:
        return Capabilities(cannot=CANNOT)

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

    def sigma_of(self, artifact: Any, y: np.ndarray, s: np.ndarray) -> float:
        sch = artifact.schedule
        raw = y[sch.index] if sch.source == "output" else (s[sch.index] if len(s) else sch.points[0])
        return sch.clip(float(raw))

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        from .scheduled_run import design_model

        return design_model(artifact, state=state, sigma=sigma)

    def simulate(self, artifact: Any, *, steps: int, x0: Any = None, reference: Any = None, noise_std: float = 0.0,
                 seed: int = 0, signals: Any = None) -> Any:  # fmt: skip
        from .scheduled_run import simulate

        return simulate(self, artifact, steps=steps, x0=x0, reference=reference, noise_std=noise_std, seed=seed,
                        signals=signals)  # fmt: skip

    def shadow(self, artifact: Any, *, like: str) -> Controller | None:
        return self.reference(artifact) if like == "reference" else self.model(artifact)

    def describe(self, artifact: Any) -> dict:
        from .scheduled_run import describe

        return describe(artifact) | super().describe(artifact)

    def without_rate_limit(self, artifact: Any) -> Any:
        from .scheduled_run import without_rate_limit

        return without_rate_limit(artifact)

    def run_report(self, artifact: Any, trace: Any, *, ran: str | None, design_model: bool) -> dict:
        from .scheduled_run import schedule_metrics

        return {"schedule": schedule_metrics(artifact, trace)}

    def report_lines(self, metrics: Mapping[str, Any]) -> list[str]:
        from .scheduled_run import schedule_lines

        return schedule_lines(metrics.get("schedule"))

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        from .scheduled_pil import image_stream

        return image_stream(artifact, target=target, board=board, status_flags=status_flags)

    def pil_check(self, artifact: Any, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray,
                  trace: Any, twin_u: np.ndarray | None, design_model: bool, check_plant: Any) -> dict:  # fmt: skip
        from .scheduled_pil import pil_check

        return pil_check(artifact, records, Y=Y, R=R, S=S, trace=trace)

    def pil_lines(self, summary: Mapping[str, Any]) -> list[str]:
        from .scheduled_pil import pil_lines

        return pil_lines(summary.get("scheduled"))

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from .scheduled_pil import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)
