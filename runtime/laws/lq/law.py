"""The observer-based LQ law in float32 (docs/design.md §2): its design (the observer-based pipeline and the float32
fidelity check), its float64 reference, the bit-exact float32 model of its C, and the host C through ctypes, each
behind :class:`~gainlink.laws.base.Controller`; its replay engines, one-step check, trace files and C export."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import flags
from ..base import Controller, Law, OneStepVerdict, Step

if TYPE_CHECKING:
    from ...proof.sampled_plant import SampledPlant
    from ...spec import PlantSpec
    from ...synthesis.pipeline import DesignResult

#: What the one-step check of this law checks a trace against (gainlink.proof.onestep).
AGAINST_FLOAT64 = "float64 law from its own state at each step"


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
        from ...engines.native import NativeLoop

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
        from ...proof.reference import ReferenceLoop

        return PythonLoop(ReferenceLoop(artifact), {"kind": "reference (float64 law)"})

    def model(self, artifact: Any) -> Controller:
        from .model import Float32Loop

        return PythonLoop(Float32Loop(artifact), {"kind": "model (the C's float32 arithmetic, bit for bit)"})

    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        return NativeLqLoop(artifact, library=library)

    def reference_block(self, artifact: Any, count: int) -> Any:
        from .block import ReferenceBlock
        from .native_block import NativeReferenceBlock, covers

        return NativeReferenceBlock(artifact, count) if covers(artifact) else ReferenceBlock(artifact, count)

    def safe_command(self, artifact: Any) -> np.ndarray:
        return np.minimum(np.maximum(artifact.u_op, artifact.u_min), artifact.u_max)

    def r_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        return artifact.Ci @ artifact.y_op

    def u_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        return np.asarray(artifact.u_op, dtype=float)

    # -- the design side ----------------------------------------------------------------------------------------

    def design(self, spec: PlantSpec) -> DesignResult:
        from ...synthesis.pipeline import synthesize_lq
        from .design import float32_check

        return synthesize_lq(spec, float32_check)

    def plant(self, artifact: Any, *, sigma: float | None = None) -> SampledPlant:
        from ...proof.sampled_plant import SampledPlant

        return SampledPlant(*artifact.design_plant(), u_op=artifact.u_op, y_op=artifact.y_op)

    def _replay(self, artifact: Any, engine: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, *,
                platform: Any) -> Any:  # fmt: skip
        if engine == "reference":
            from ...proof.reference import ReferenceLoop

            return ReferenceLoop(artifact).run(Y, R)
        if engine == "model":
            from .model import Float32Loop

            return Float32Loop(artifact).run(Y, R)
        if engine == "native":
            from ...engines.native import NativeLoop

            return NativeLoop(artifact).run(Y, R)
        from ...engines.native import trace_from_raw
        from ...engines.qemu import run_raw

        raw = run_raw(artifact, Y, R, target=platform.target.name, board=platform.board.name)
        return trace_from_raw(raw, m=artifact.m)

    def one_step(
        self, artifact: Any, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, trace: Any, *, engine: str | None
    ) -> tuple[OneStepVerdict, ...]:
        from ...proof.onestep import one_step_check

        return (OneStepVerdict(AGAINST_FLOAT64, one_step_check(artifact, Y, R, trace)),)

    def trace_numeric(self, engine: str | None) -> str | None:
        """The numeric format a replay output of ``engine`` names in its first line (none for the float32 law)."""
        return None

    def trace_text(self, artifact: Any, trace: Any, t: np.ndarray | None = None, *, engine: str | None = None) -> str:
        from ...proof.replay_io import format_trace

        return format_trace(trace, t, numeric=self.trace_numeric(engine))

    def read_trace(self, path: str | Path, artifact: Any) -> Any:
        from ...proof.replay_io import read_trace

        return read_trace(path, artifact, numeric=self.trace_numeric(None) or "float32")

    def records_trace(self, artifact: Any, records: np.ndarray) -> Any:
        from ...proof.reference import Trace

        a = artifact
        sat = ((records["sat"][:, None] >> np.arange(a.m)) & 1).astype(bool)
        return Trace(u=records["u"].astype(float), saturated=sat, xh=records["xh"].astype(float),
                     z=records["z"][:, : a.q].astype(float), fault=records["status"] == -2)  # fmt: skip

    # -- what the design and replay commands print --------------------------------------------------------------

    def design_lines(self, result: DesignResult, path: Path) -> list[str]:
        """What ``gainlink design`` prints of ``result``, written to ``path``: gains, poles, margins, the operating
        point, the checks of the loop and of the law's arithmetic."""
        return [*_gains_lines(result), *_checks_lines(result), *self._arithmetic_lines(result),
                f"  wrote {path} (sha256 {result.artifact['sha256'][:16]})"]  # fmt: skip

    def _arithmetic_lines(self, result: DesignResult) -> list[str]:
        """The check of the law's arithmetic: the float32 fidelity (none when the spec switched it off)."""
        f = result.float32
        if f is None:
            return []
        realization = result.artifact.get("realization", {}).get("kind", "as_designed")
        return [
            f"  float32 in closed loop ({realization} realisation, {f.steps} steps, noise, reference step, "
            f"saturating disturbance): max |u32 - u64| {f.max_rel_u:.3g} of the limit span, max |y32 - y64| "
            f"{f.max_rel_y:.3g} of the output excursion ({'within' if f.ok else 'ABOVE'} {f.threshold:g})"
        ]

    def design_json(self, result: DesignResult, path: Path) -> dict:
        """``gainlink design --json``."""
        from ...synthesis.analysis import complex_pairs

        a = result.artifact
        return {
            "artifact": str(path),
            "sha256": a["sha256"],
            "K": a["K"],
            "L": a["L"],
            "Ki": a.get("Ki"),
            "controller_poles": complex_pairs(result.controller_poles),
            "observer_poles": complex_pairs(result.observer_poles),
            "margins": a["checks"]["margins"],
            "u_op": a.get("u_op"),
            "y_op": a.get("y_op"),
            "compensator": a["checks"]["compensator"],
            "float32": a["checks"].get("float32"),
            "fixed_point": None,
            "realization": a.get("realization", {}).get("kind", "as_designed"),
            "warnings": result.warnings,
        }

    def design_plots(self, artifact: Any) -> tuple[dict[str, bytes], str | None]:
        """``design --plots``: the loop broken at each actuator and the closed-loop step (PNG files by name), and
        why nothing was drawn (None: drawn)."""
        from ...synthesis.loop_plots import design_plots

        return design_plots(artifact), None

    def open_loop_note(self, artifact: Any) -> str:
        """What the compensator's stability says about two replays compared open loop."""
        from ...synthesis.compensator import compensator_stability

        comp = compensator_stability(artifact)
        if comp.stable:
            return comp.describe()
        return (
            f"{comp.describe()}; replayed open loop, rounding grows like {comp.radius_without_integrators:.3g}^k"
            ": the one-step check is the verdict"
        )

    # -- the closed loop (gainlink.laws.hooks.LoopHooks) ------------------------------------------------------

    def integrator_columns(self, artifact: Any) -> slice | None:
        return slice(artifact.n, artifact.n + artifact.q)

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        from .run import design_model

        return design_model(artifact, state=state, deviation=deviation)

    def simulate(self, artifact: Any, *, steps: int, x0: Any = None, reference: Any = None, noise_std: float = 0.0,
                 seed: int = 0, signals: Any = None) -> Any:  # fmt: skip
        from ...errors import DataError
        from ...proof.simulation import simulate_linear

        if signals is not None and np.size(signals):
            raise DataError(f"artifact {artifact.name} is not scheduled: it takes no external scheduling signals")
        return simulate_linear(artifact, steps=steps, x0=x0, reference=reference, noise_std=noise_std, seed=seed)

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        from .run import image_stream

        return image_stream(artifact, target=target, board=board)

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from .run import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)

    def describe(self, artifact: Any) -> dict:
        from .run import describe

        return describe(artifact) | super().describe(artifact)


def _gains_lines(result: DesignResult) -> list[str]:
    """The design's summary line, gains, poles and margins."""
    a = result.artifact
    lines = [
        f"{a['name']}: n={a['n']} m={a['m']} p={a['p']} q={a['q']}, Ts={a['Ts']:g} s, "
        f"{a['design']['controller']['method']} + {a['design']['observer']['method']} "
        f"({a['observer_form']}), anti-windup {a['anti_windup']}"
    ]
    with np.printoptions(precision=5, suppress=True, linewidth=110):
        lines.append(f"  K  = {np.array(a['K'])}".replace("\n", "\n       "))
        if a["q"]:
            lines.append(f"  Ki = {np.array(a['Ki'])}".replace("\n", "\n       "))
    lines.append(
        f"  controller poles |z| max {np.max(np.abs(result.controller_poles)):.5f}, "
        f"observer poles |z| max {np.max(np.abs(result.observer_poles)):.5f}, "
        f"closed loop spectral radius {a['checks']['spectral_radius']:.5f}"
    )
    for mg in result.margins:
        up = "inf" if mg.gain_margin_up_db is None else f"+{mg.gain_margin_up_db:.1f}"
        down = "-inf" if mg.gain_margin_down_db is None else f"{mg.gain_margin_down_db:.1f}"
        pm = "n/a" if mg.phase_margin_deg is None else f"{mg.phase_margin_deg:.1f} deg"
        lines.append(f"  margins at input {mg.input}: gain {up} / {down} dB, phase {pm}")
    return lines


def _checks_lines(result: DesignResult) -> list[str]:
    """The operating point and the checks of the loop: compensator, dead times."""
    a = result.artifact
    lines = []
    if "u_op" in a or "y_op" in a:
        op = [
            f"{name}={v:.6g}"
            for key, names in (("u_op", a["signals"]["inputs"]), ("y_op", a["signals"]["outputs"]))
            for name, v in zip(names, a.get(key, [0.0] * len(names)))
        ]
        lines.append(f"  operating point: {', '.join(op)} (samples, references and commands are absolute)")
    lines.append(f"  {result.compensator.describe()}")
    if result.dead_time is not None:
        lines.append(f"  {result.dead_time.describe()}")
    return lines
