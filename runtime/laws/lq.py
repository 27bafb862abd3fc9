"""The observer-based LQ law in float32 (docs/design.md §2): its float64 reference, the bit-exact float32 model of
its C, and the host C through ctypes, each behind :class:`~gainlink.laws.base.Controller`."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from . import flags
from .base import Controller, Law, Step


def sat_bits(saturated: np.ndarray) -> int:
    """The saturation mask of per-input booleans (bit j: input j)."""
    return int(np.sum(np.asarray(saturated, dtype=np.int64) << np.arange(np.asarray(saturated).size)))


class PythonLoop:
    """A Python law with ``step(y, r) -> StepResult`` (``u, saturated, fault``) as a :class:`Controller`."""

    def __init__(self, loop: Any, describe: dict) -> None:
        self.loop, self.describe = loop, describe

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample (``s`` unused: this law is not scheduled)."""
        res = self.loop.step(y, r)
        return Step(u=np.asarray(res.u, dtype=float), flags=flags.FAULT if res.fault else 0,
                    sat=0 if res.fault else sat_bits(res.saturated))  # fmt: skip

    def reset(self) -> None:
        """Back to the start state."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """``[xh, z]`` (the estimate and the integrators, in real units)."""
        return np.concatenate([np.asarray(self.loop.xh, dtype=float), np.asarray(self.loop.z, dtype=float)])


class NativeLqLoop:
    """The host C's ``gl_loop_t`` (:class:`~gainlink.engines.native.NativeLoop`) as a :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from ..engines.native import NativeLoop

        self.loop = NativeLoop(artifact, library=library)
        self.describe = {"kind": "firmware (host C loop, ctypes)", "library": str(self.loop.library)}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample through ``gl_loop_step``."""
        out = self.loop.step(y, r)
        fault = out.status == -2  # GL_ERR_NANINF
        return Step(u=np.asarray(out.u, dtype=float), flags=flags.FAULT if fault else 0,
                    sat=0 if fault else int(out.sat_mask))  # fmt: skip

    def reset(self) -> None:
        """``gl_loop_reset``."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """Not read one step at a time: the C loop's estimate comes with a block run (``NativeLoop.run_raw``)."""
        raise NotImplementedError("the host C loop's state is read with NativeLoop.run_raw")


class LqLaw(Law):
    """The positional observer-based law (predictor or current form, LQ/LQI/placement/given gains)."""

    structure = "lq"
    numerics = ("float32",)

    @property
    def label(self) -> str:
        return "float32"

    def reference(self, artifact: Any) -> Controller:
        from ..proof.reference import ReferenceLoop

        return PythonLoop(ReferenceLoop(artifact), {"kind": "reference (float64 law)"})

    def model(self, artifact: Any) -> Controller:
        from ..proof.float32_law import Float32Loop

        return PythonLoop(Float32Loop(artifact), {"kind": "model (the C's float32 arithmetic, bit for bit)"})

    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        return NativeLqLoop(artifact, library=library)

    def safe_command(self, artifact: Any) -> np.ndarray:
        return np.minimum(np.maximum(artifact.u_op, artifact.u_min), artifact.u_max)

    def r_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        return artifact.Ci @ artifact.y_op

    def integrators(self, artifact: Any, states: np.ndarray) -> np.ndarray | None:
        return np.asarray(states)[:, artifact.n : artifact.n + artifact.q]

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        from .lq_run import design_model

        return design_model(artifact, state=state, deviation=deviation)

    def simulate(self, artifact: Any, *, steps: int, x0: Any = None, reference: Any = None, noise_std: float = 0.0,
                 seed: int = 0, signals: Any = None) -> Any:  # fmt: skip
        from ..errors import DataError
        from ..proof.simulation import simulate_linear

        if signals is not None and np.size(signals):
            raise DataError(f"artifact {artifact.name} is not scheduled: it takes no external scheduling signals")
        return simulate_linear(artifact, steps=steps, x0=x0, reference=reference, noise_std=noise_std, seed=seed)

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        from .lq_run import image_stream

        return image_stream(artifact, target=target, board=board)

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from .lq_run import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)

    def describe(self, artifact: Any) -> dict:
        from .lq_run import describe

        return describe(artifact) | super().describe(artifact)
