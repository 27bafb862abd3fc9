"""The observer-based LQ law on integers (``numeric = "q31" | "q15"``, docs/design.md "Fixed point"): its design (the
observer-based pipeline and the fixed-point certificate), the float64 design law it is certified against, the
bit-exact integer model of its C, and the host C through ctypes; its replay engines (the integer C), its one-step
check (bit for bit against the integer law) and its trace files (which name their numeric format)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import flags
from ..base import Controller, OneStepVerdict, Step
from ..lq.law import AGAINST_FLOAT64, LqLaw, PythonLoop, sat_bits

if TYPE_CHECKING:
    from ...spec import PlantSpec
    from ...synthesis.pipeline import DesignResult


def _as_float32(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, dtype=np.float32).astype(np.float64)


class FixedModel:
    """The integer model (:class:`~gainlink.laws.fixed.model.FixedPointLoop`) as a :class:`Controller`."""

    def __init__(self, artifact: Any) -> None:
        from .model import FixedPointLoop

        self.loop = FixedPointLoop(artifact)
        self.f_u = np.array(artifact.checks["fixed_point"]["formats"]["u"])
        self.describe = {"kind": "model (the integer law, bit for bit)"}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample as the C takes it (float32), clipped to the declared ranges, quantised, stepped on integers."""
        res = self.loop.step_samples(_as_float32(y), _as_float32(r))
        bits = flags.FAULT if res.fault else 0
        bits |= flags.CLIPPED if (res.clipped_y.any() or res.clipped_r.any()) else 0
        bits |= flags.OVERFLOW if res.overflow else 0
        return Step(u=self._returned(res.U), flags=bits,
                    sat=0 if res.fault else sat_bits(res.saturated), word=np.asarray(res.U))  # fmt: skip

    def _returned(self, U: np.ndarray) -> np.ndarray:
        """The float the C returns for the words ``U``: ``(float)U * 2^-f`` (gl_fixed.c; exact scaling by a power
        of two after the one rounding of the word to float32)."""
        return np.asarray(U, dtype=np.float32).astype(np.float64) * np.exp2(-self.f_u.astype(np.float64))

    def reset(self) -> None:
        """Back to the start state."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """``[xh, z]`` (the integer words in real units)."""
        return np.concatenate([self.loop.xh, self.loop.z])


class FixedNative:
    """The host C's integer loop (:class:`~gainlink.laws.fixed.native.FixedNativeLoop`) as a
    :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from .native import FixedNativeLoop

        self.loop = FixedNativeLoop(artifact, library=library)
        self.f, self.q = artifact.checks["fixed_point"]["formats"], artifact.q
        self.describe = {"kind": f"firmware (host C {self.loop.law} fixed-point loop, ctypes)",
                         "library": str(self.loop.library)}  # fmt: skip

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample through ``gl_fixed_step``."""
        out = self.loop.step(y, r)
        rec = self.loop.last_record  # its flags are the status flags (the one table)
        return Step(u=np.asarray(out.u, dtype=float), flags=int(rec["flags"]), sat=int(out.sat_mask),
                    word=np.array(rec["U"], dtype=np.int64))  # fmt: skip

    def reset(self) -> None:
        """``gl_fixed_reset``."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """``[xh, z]`` of the last step's record (the integer words in real units)."""
        from .qformat import real

        rec, f = self.loop.last_record, self.f
        return np.concatenate([real(np.asarray(rec["XH"], dtype=np.int64), f["xh"]),
                               real(np.asarray(rec["Z"], dtype=np.int64)[: self.q], f["z"])])  # fmt: skip


class FixedLaw(LqLaw):
    """The lq structure with integer arithmetic (a pair of its own: its model and its C differ)."""

    numerics = ("q31", "q15")

    @property
    def label(self) -> str:
        return self.numeric

    def reference(self, artifact: Any) -> Controller:
        from ...proof.reference import ReferenceLoop

        return PythonLoop(ReferenceLoop(artifact), {"kind": "reference (float64 design law)"})

    def model(self, artifact: Any) -> Controller:
        return FixedModel(artifact)

    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        return FixedNative(artifact, library=library)

    # -- the design side ----------------------------------------------------------------------------------------

    def design(self, spec: PlantSpec) -> DesignResult:
        from ...synthesis.pipeline import synthesize_lq
        from .design import fixed_point_check

        return synthesize_lq(spec, fixed_point_check)

    def _replay(self, artifact: Any, engine: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, *,
                platform: Any) -> Any:  # fmt: skip
        if engine == "reference":
            from ...proof.reference import ReferenceLoop

            return ReferenceLoop(artifact).run(Y, R)
        if engine == "model":  # on the float32 samples the C takes: the trace native and qemu give, bit for bit
            from .model import FixedPointLoop

            return FixedPointLoop(artifact).run(_as_float32(Y), _as_float32(R))
        from . import engines as fixed_engine

        if engine == "native":
            return fixed_engine.run_native(artifact, Y, R)
        return fixed_engine.run_qemu(artifact, Y, R, target=platform.target.name, board=platform.board.name)

    def one_step(
        self, artifact: Any, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, trace: Any, *, engine: str | None
    ) -> tuple[OneStepVerdict, ...]:
        """The ``reference`` engine's trace against the float64 law within the float32 bound; any other (a trace of
        the integer law, or a trace file of this law's format) bit for bit against the integer law."""
        from ...proof.onestep import one_step_check
        from .onestep import fixed_one_step_check, trace_words

        if engine == "reference":
            return (OneStepVerdict(AGAINST_FLOAT64, one_step_check(artifact, Y, R, trace)),)
        words = trace_words(artifact, trace, f"the trace of engine {engine}" if engine else "the trace")
        return (OneStepVerdict("", fixed_one_step_check(artifact, Y, R, words)),)

    def trace_numeric(self, engine: str | None) -> str | None:
        """``float64`` for the ``reference`` engine's trace, else the law's own format (``q31``, ``q15``)."""
        return "float64" if engine == "reference" else self.numeric

    def records_trace(self, artifact: Any, records: np.ndarray) -> Any:
        """The integer law's records as the real values its words mean (``replay --engine native``'s trace)."""
        from .engines import trace_from_run
        from .firmware import FixedRun

        return trace_from_run(artifact, FixedRun.from_records(records, artifact.q))

    def host_run_note(self, artifact: Any, records: np.ndarray, trace: Any) -> str:
        """The integer law's counts: saturated and refused steps, and those its ranges clipped or that overflowed."""
        from .firmware import CLIPPED, OVERFLOW

        flags = np.asarray(records["flags"])
        saturated, refused = int(trace.saturated.any(axis=1).sum()), int(trace.fault.sum())
        return (
            f" ({self.label} integer law): {saturated} saturated, {refused} refused, "
            f"{int(((flags & CLIPPED) != 0).sum())} clipped, {int(((flags & OVERFLOW) != 0).sum())} overflowed"
        )

    def _arithmetic_lines(self, result: DesignResult) -> list[str]:
        """The certificate's lines, and the deviation measured in closed loop beside the certified bound."""
        from .certificate import describe as describe_fixed_point

        cert, measured = result.fixed_point, result.artifact["checks"]["fixed_point"]["measured"]
        got, bound = measured["max_abs_u_unsaturated"], measured["bound_closed_loop"]
        worst = ", ".join(f"{name} {g:.3g} (bound {b:.3g})" for name, g, b in zip(cert.names["u"], got, bound))
        return [f"  {line}" for line in describe_fixed_point(cert)] + [
            f"    measured in closed loop ({measured['steps']} steps, noise, reference step, saturating disturbance): "
            f"unsaturated, against the float64 law with the quantised coefficients (the rounding alone, closed loop) "
            f"{worst} over {measured['unsaturated_steps']} steps; whole run "
            f"{measured['max_rel_u_quantised']:.3g} of the span against the float64 law with the same coefficients "
            f"and clip, {measured['max_rel_u']:.3g} against the design's"
            + (f" ({measured['clipped_steps']} steps clipped to the ranges)" if measured["clipped_steps"] else "")
            + ("" if not measured["overflow"] else f"; SECOND-LINE SATURATION on {', '.join(measured['overflow'])}")
        ]

    def design_json(self, result: DesignResult, path: Path) -> dict:
        """``gainlink design --json``: the float32 law's, with the certificate."""
        return super().design_json(result, path) | {"fixed_point": result.artifact["checks"]["fixed_point"]}

    def read_trace(self, path: str | Path, artifact: Any) -> Any:
        """A trace of this law's format, refused in one line unless its commands are words of the artifact's
        command format (read before anything is replayed, so a wrong file writes nothing)."""
        from .onestep import trace_words

        trace = super().read_trace(path, artifact)
        trace_words(artifact, trace, f"comparison file {path}")
        return trace

    # -- the closed loop (gainlink.laws.hooks.LoopHooks) ------------------------------------------------------

    def run_report(self, artifact: Any, trace: Any, *, ran: str | None, design_model: bool) -> dict:
        if ran is None:  # the float64 design law ran: nothing of the integer law to check
            return {}
        from .run import run_check

        check = run_check(artifact, trace, model=self.model(artifact), ran=ran, design_model=design_model)
        return {"fixed_point": check}

    def report_lines(self, metrics: Mapping[str, Any]) -> list[str]:
        from .run import summary_lines

        return summary_lines(metrics.get("fixed_point"))

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        from .pil import image_stream

        return image_stream(artifact, target=target, board=board)

    def pil_check(self, artifact: Any, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray,
                  trace: Any, twin_u: np.ndarray | None, design_model: bool, check_plant: Any) -> dict:  # fmt: skip
        from .pil import pil_check

        return pil_check(artifact, records, Y=Y, R=R, design_u=twin_u, design_model=design_model,
                         check_plant=check_plant)  # fmt: skip

    def pil_lines(self, summary: Mapping[str, Any]) -> list[str]:
        from .pil import pil_lines

        return pil_lines(summary.get("fixed_point"))

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from .pil import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)
