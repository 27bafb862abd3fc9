"""The observer-based LQ law on integers (``numeric = "q31" | "q15"``, docs/design.md "Fixed point"): the float64
design law it is certified against, the bit-exact integer model of its C, and the host C through ctypes."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from . import flags
from .base import Controller, Step
from .lq import LqLaw, PythonLoop, sat_bits

#: gl_fixed.h's GL_FX_FAULT, GL_FX_CLIPPED, GL_FX_OVERFLOW as the status flags.
_FX_FLAGS = ((1, flags.FAULT), (2, flags.CLIPPED), (4, flags.OVERFLOW))


def status_flags(fx: int) -> int:
    """The status flags of the fixed-point C's own flag word."""
    return sum(bit for fx_bit, bit in _FX_FLAGS if fx & fx_bit)


def _as_float32(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, dtype=np.float32).astype(np.float64)


class FixedModel:
    """The integer model (:class:`~gainlink.proof.fixed_law.FixedPointLoop`) as a :class:`Controller`."""

    def __init__(self, artifact: Any) -> None:
        from ..proof.fixed_law import FixedPointLoop

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
    """The host C's integer loop (:class:`~gainlink.engines.fixed_native.FixedNativeLoop`) as a
    :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from ..engines.fixed_native import FixedNativeLoop

        self.loop = FixedNativeLoop(artifact, library=library)
        self.f, self.q = artifact.checks["fixed_point"]["formats"], artifact.q
        self.describe = {"kind": f"firmware (host C {self.loop.law} fixed-point loop, ctypes)",
                         "library": str(self.loop.library)}  # fmt: skip

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample through ``gl_fixed_step``."""
        out = self.loop.step(y, r)
        rec = self.loop.last_record
        return Step(u=np.asarray(out.u, dtype=float), flags=status_flags(int(rec["flags"])),
                    sat=int(out.sat_mask), word=np.array(rec["U"], dtype=np.int64))  # fmt: skip

    def reset(self) -> None:
        """``gl_fixed_reset``."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """``[xh, z]`` of the last step's record (the integer words in real units)."""
        from ..proof.fixed_format import real

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
        from ..proof.reference import ReferenceLoop

        return PythonLoop(ReferenceLoop(artifact), {"kind": "reference (float64 design law)"})

    def model(self, artifact: Any) -> Controller:
        return FixedModel(artifact)

    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        return FixedNative(artifact, library=library)

    def run_report(self, artifact: Any, trace: Any, *, ran: str | None, design_model: bool) -> dict:
        if ran is None:  # the float64 design law ran: nothing of the integer law to check
            return {}
        from .fixed_run import run_check

        check = run_check(artifact, trace, model=self.model(artifact), ran=ran, design_model=design_model)
        return {"fixed_point": check}

    def report_lines(self, metrics: Mapping[str, Any]) -> list[str]:
        from .fixed_run import summary_lines

        return summary_lines(metrics.get("fixed_point"))

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        from .fixed_pil import image_stream

        return image_stream(artifact, target=target, board=board, status_flags=status_flags)

    def pil_check(self, artifact: Any, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray,
                  trace: Any, twin_u: np.ndarray | None, design_model: bool, check_plant: Any) -> dict:  # fmt: skip
        from .fixed_pil import pil_check

        return pil_check(artifact, records, Y=Y, R=R, design_u=twin_u, design_model=design_model,
                         check_plant=check_plant)  # fmt: skip

    def pil_lines(self, summary: Mapping[str, Any]) -> list[str]:
        from .fixed_pil import pil_lines

        return pil_lines(summary.get("fixed_point"))

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from .fixed_pil import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)
