"""The scheduled law (velocity form, docs/design.md "Scheduled law"): its design (every point through the observer-
based law's design, then the scheduled checks), its float64 reference, the bit-exact float32 model of its C, and the
host C through ctypes; its replay engines, one-step checks, trace files and C export."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import flags
from ..base import Controller, Law, OneStepVerdict, Step
from ..lq.law import AGAINST_FLOAT64, LqLaw, sat_bits

if TYPE_CHECKING:
    from ...proof.sampled_plant import SampledPlant
    from ...spec import PlantSpec
    from ...synthesis.pipeline import DesignResult

log = logging.getLogger(__name__)

#: What a trace of the C is checked against: the float64 law within the float32 bound (.scheduled_onestep), and its
#: float32 model bit for bit (gainlink.laws.scheduled.model).
AGAINST_FLOAT32_BOUND = "float64 law from its own state at each step, within the float32 bound"
AGAINST_FLOAT32_MODEL = "the C's float32 arithmetic, bit for bit, from its own state at each step"

#: The scheduled law's own sigma flags (laws.scheduled.reference) as the status flags.
_SIGMA_FLAGS = ((1, flags.SIGMA_HELD), (2, flags.SIGMA_CLIPPED), (4, flags.SIGMA_RATE))


def _float32_check(artifact: dict, spec: PlantSpec, warnings: list[str]) -> tuple[dict, Any]:
    """The sealed scheduled ``artifact`` with its float32 fidelity at a sigma sweep in ``checks.float32`` (and a
    warning naming where and the remedies when it is above the threshold); unchanged, with None, when the spec
    switched the float32 check off."""
    from ...shipping.artifact import from_dict, seal
    from .fidelity import scheduled_fidelity

    if not spec.implementation.float32_check:
        return artifact, None
    fidelity = scheduled_fidelity(from_dict(artifact))
    data = dict(artifact, checks=dict(artifact["checks"], float32=fidelity.to_dict()))
    if not fidelity.ok:
        warnings.append(fidelity.warning(spec.schedule.sigma))
        log.warning(warnings[-1])
    return seal(data), fidelity


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
    """The host C's ``gl_sched_t`` (:class:`~gainlink.laws.scheduled.native.NativeScheduledLoop`) as a
    :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from .native import NativeScheduledLoop

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

    def state(self) -> np.ndarray:
        """``gl_sched_state``: the C loop's state vector."""
        return self.loop.state().astype(float)


class ScheduledLaw(Law):
    """The velocity-form law scheduled on sigma, interpolating the per-point coefficients."""

    structure = "scheduled"
    numerics = ("float32",)

    @property
    def label(self) -> str:
        return "scheduled-float32"

    def reference(self, artifact: Any) -> Controller:
        from .reference import ScheduledLoop

        return ScheduledPython(ScheduledLoop(artifact), {"kind": "reference (float64 scheduled law)"})

    def model(self, artifact: Any) -> Controller:
        from .model import ScheduledFloat32Loop

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

    def u_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        s = artifact.schedule
        return np.asarray(s.u_op[0] if sigma is None else s.trim_at(s.clip(sigma))[0], dtype=float)

    def externals(self, artifact: Any) -> tuple[str, ...]:
        return tuple(artifact.schedule.external)

    #: The scenario plant that is this law's own model (``plant = "artifact"`` asks for it).
    own_plant = "lpv_model"

    # -- the design side ----------------------------------------------------------------------------------------

    def design(self, spec: PlantSpec) -> DesignResult:
        """Every point through the observer-based law's design (float32), then the scheduled checks, then the
        float32 fidelity at a sigma sweep (:mod:`.scheduled_fidelity`; off when the spec switches the float32 check
        off)."""
        from ...synthesis.pipeline import DesignResult
        from .design import synthesize_scheduled

        artifact, design, warnings = synthesize_scheduled(spec, LqLaw().design)
        artifact, float32 = _float32_check(artifact, spec, warnings)
        first = design.results[0]
        return DesignResult(artifact=artifact, controller_poles=first.controller_poles,
                            observer_poles=first.observer_poles, closed_loop_poles=first.closed_loop_poles,
                            margins=first.margins, warnings=warnings, compensator=first.compensator,
                            float32=float32, schedule=design)  # fmt: skip

    def plant(self, artifact: Any, *, sigma: float | None = None) -> SampledPlant:
        """The design model frozen at ``sigma`` (the first point by default): the points' sampled plants and trims
        interpolated there."""
        from ...proof.sampled_plant import SampledPlant

        S = artifact.schedule
        at = S.clip(S.points[0] if sigma is None else sigma)
        u_op, y_op = S.trim_at(at)
        return SampledPlant(*S.plant_at(at), u_op=u_op, y_op=y_op)

    def _replay(self, artifact: Any, engine: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, *,
                platform: Any) -> Any:  # fmt: skip
        if engine == "reference":
            from .reference import ScheduledLoop

            return ScheduledLoop(artifact).run(Y, R, S)
        if engine == "model":
            from .model import ScheduledFloat32Loop

            return ScheduledFloat32Loop(artifact).run(Y, R, S)
        if engine == "native":
            from .native import run

            return run(artifact, Y, R, S)
        from .qemu import run as run_qemu

        return run_qemu(artifact, Y, R, S, target=platform.target.name, board=platform.board.name)

    def one_step(
        self, artifact: Any, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, trace: Any, *, engine: str | None
    ) -> tuple[OneStepVerdict, ...]:
        """The float64 law's trace (``reference``, or a file that names ``float64`` or no format) against the float64
        law within float64's bound; a trace of the C (``native``, ``qemu``, its ``model``, or a file that names
        ``float32``) against the float64 law within the float32 bound (:mod:`.scheduled_onestep`) and bit for bit
        against the C's float32 model."""
        from .onestep import float32_bound_check
        from .replay import one_step_check

        c_trace = engine in ("model", "native", "qemu") or (engine is None and trace.numeric == "float32")
        if c_trace:
            return (
                OneStepVerdict(AGAINST_FLOAT32_BOUND, float32_bound_check(artifact, Y, R, S, trace)),
                OneStepVerdict(AGAINST_FLOAT32_MODEL, one_step_check(artifact, Y, R, S, trace, float32=True)),
            )
        return (OneStepVerdict(AGAINST_FLOAT64, one_step_check(artifact, Y, R, S, trace)),)

    def trace_numeric(self, engine: str | None) -> str:
        """``float64`` for the ``reference`` engine's trace, ``float32`` for the C's and its model's."""
        return "float64" if engine == "reference" else "float32"

    def trace_text(self, artifact: Any, trace: Any, t: np.ndarray | None = None, *, engine: str | None = None) -> str:
        from .replay import format_trace

        return format_trace(artifact, trace, t, numeric=self.trace_numeric(engine))

    def read_trace(self, path: str | Path, artifact: Any) -> Any:
        from .replay import read_trace

        return read_trace(path, artifact)

    def records_trace(self, artifact: Any, records: np.ndarray) -> Any:
        from .native import raw_of_records, scheduled_trace_from_raw

        return scheduled_trace_from_raw(raw_of_records(records), a=artifact)

    # -- what the design and replay commands print --------------------------------------------------------------

    def design_lines(self, result: DesignResult, path: Path) -> list[str]:
        """What ``gainlink design`` prints of a scheduled design: every point, the grid, the verdict on a moving
        sigma."""
        from .design import describe_schedule

        a = result.artifact
        sch, s = a["checks"]["schedule"], a["schedule"]
        return [
            f"{a['name']}: n={a['n']} m={a['m']} p={a['p']} q={a['q']}, Ts={a['Ts']:g} s, scheduled on {sch['sigma']}"
            f" ({s['sigma']['source']}) at {', '.join(f'{v:g}' for v in s['points'])}: "
            f"{a['design']['controller']['method']} + {a['design']['observer']['method']} ({a['observer_form']}) per "
            "point, velocity form",
            *(f"  {line}" for line in describe_schedule(sch)),
            f"  coefficients that vary between points (interpolated by the C): {', '.join(s['varying']) or 'none'}",
            *([f"  {result.float32.describe(sch['sigma'])}"] if result.float32 is not None else []),
            f"  wrote {path} (schema 2, sha256 {a['sha256'][:16]})",
        ]

    def design_json(self, result: DesignResult, path: Path) -> dict:
        """``gainlink design --json`` of a scheduled design."""
        a = result.artifact
        return {"artifact": str(path), "sha256": a["sha256"], "schedule": a["checks"]["schedule"],
                "rate_max": a["schedule"]["rate_max"], "rate_certified": a["schedule"]["rate_certified"],
                "float32": a["checks"].get("float32"), "warnings": result.warnings}  # fmt: skip

    def design_plots(self, artifact: Any) -> tuple[dict[str, bytes], str | None]:
        """Nothing: the loop a plot would show changes along sigma."""
        return {}, f"not drawn for a scheduled law (its loop changes along {artifact.schedule.sigma})"

    def analysis_lines(self, report: Any) -> list[str]:
        """The points and their verdicts, when the spec designs (``report.schedule``: its ``checks.schedule``)."""
        from .design import describe_schedule

        if not report.schedule:
            return []
        return [f"  scheduled on {report.schedule['sigma']} (the plant above is the first point's):",
                *(f"    {line}" for line in describe_schedule(report.schedule))]  # fmt: skip

    def open_loop_note(self, artifact: Any) -> str:
        """Where each point's compensator stability is recorded."""
        return "the scheduled law's compensator at each point is in checks.schedule.points"

    # -- the closed loop (gainlink.laws.hooks.LoopHooks) ------------------------------------------------------

    def sigma_of(self, artifact: Any, y: np.ndarray, s: np.ndarray) -> float:
        sch = artifact.schedule
        raw = y[sch.index] if sch.source == "output" else (s[sch.index] if len(s) else sch.points[0])
        return sch.clip(float(raw))

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        from .run import design_model

        return design_model(artifact, state=state, sigma=sigma)

    def simulate(self, artifact: Any, *, steps: int, x0: Any = None, reference: Any = None, noise_std: float = 0.0,
                 seed: int = 0, signals: Any = None) -> Any:  # fmt: skip
        from .run import simulate

        return simulate(self, artifact, steps=steps, x0=x0, reference=reference, noise_std=noise_std, seed=seed,
                        signals=signals)  # fmt: skip

    def shadow(self, artifact: Any, *, like: str) -> Controller | None:
        return self.reference(artifact) if like == "reference" else self.model(artifact)

    def describe(self, artifact: Any) -> dict:
        from .run import describe

        return describe(artifact) | super().describe(artifact)

    def without_rate_limit(self, artifact: Any) -> Any:
        from .run import without_rate_limit

        return without_rate_limit(artifact)

    def run_report(self, artifact: Any, trace: Any, *, ran: str | None, design_model: bool) -> dict:
        from .run import schedule_metrics

        return {"schedule": schedule_metrics(artifact, trace)}

    def report_lines(self, metrics: Mapping[str, Any]) -> list[str]:
        from .run import schedule_lines

        return schedule_lines(metrics.get("schedule"))

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        from .pil import image_stream

        return image_stream(artifact, target=target, board=board)

    def pil_check(self, artifact: Any, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray,
                  trace: Any, twin_u: np.ndarray | None, design_model: bool, check_plant: Any) -> dict:  # fmt: skip
        from .pil import pil_check

        return pil_check(artifact, records, Y=Y, R=R, S=S, trace=trace, status_flags=status_flags)

    def pil_lines(self, summary: Mapping[str, Any]) -> list[str]:
        from .pil import pil_lines

        return pil_lines(summary.get("scheduled"))

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from .pil import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)
