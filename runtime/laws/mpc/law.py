"""The MPC law in float32 (docs/design.md, "MPC (the fourth law)"): its design, its float64 model of the algorithm,
the bit-exact float32 model of its C, the host C through ctypes, its replay engines, one-step checks and trace files.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import DataError
from ..base import Controller, Law, OneStepVerdict
from ..lq import LqLaw
from .arith import Arith, Float32
from .controllers import MpcController, MpcNative, trace_of_records
from .onestep import one_step_check
from .step import MpcLoop, MpcTrace

if TYPE_CHECKING:
    from ...proof.sampled_plant import SampledPlant
    from ...spec import PlantSpec
    from ...synthesis.pipeline import DesignResult

AGAINST_MODEL = "the C's float32 arithmetic, bit for bit, from its own state at each step (its iteration count too)"
AGAINST_FLOAT64 = ("the float64 algorithm from the same state with the same iteration count, within the solver's own "
                   "tolerance (measured, not a proved float32 bound)")  # fmt: skip


class MpcLaw(Law):
    """Linear MPC on the observer-based law's estimate and integrators, solved by ADMM on cached Riccati gains."""

    structure = "mpc"
    numerics = ("float32",)

    @property
    def label(self) -> str:
        return "mpc-float32"

    def reference(self, artifact: Any) -> Controller:
        return MpcController(MpcLoop(artifact, Arith()), {"kind": "reference (the MPC algorithm in float64)"})

    def model(self, artifact: Any) -> Controller:
        return MpcController(MpcLoop(artifact, Float32()), {"kind": "model (the MPC C's float32 arithmetic)"})

    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        return MpcNative(artifact, library=library)

    def u_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        return np.asarray(artifact.u_op, dtype=float)

    def safe_command(self, artifact: Any) -> np.ndarray:
        return np.minimum(np.maximum(artifact.u_op, artifact.u_min), artifact.u_max)

    def r_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        return artifact.Ci @ artifact.y_op

    # -- the design side ----------------------------------------------------------------------------------------

    def design(self, spec: PlantSpec) -> DesignResult:
        """The observer-based pipeline with the ``mpc`` block as the law's implementation step
        (:mod:`.design`)."""
        from ...synthesis.pipeline import synthesize_lq
        from .design import mpc_check

        return synthesize_lq(spec, mpc_check)

    def plant(self, artifact: Any, *, sigma: float | None = None) -> SampledPlant:
        return LqLaw().plant(artifact)

    def _replay(self, artifact: Any, engine: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, *,
                platform: Any) -> Any:  # fmt: skip
        if engine in ("reference", "model"):
            return MpcLoop(artifact, Arith() if engine == "reference" else Float32()).run(Y, R)
        if engine == "native":
            from ...firmware.host import HostLaw

            return trace_of_records(HostLaw(artifact).run(Y, R))
        from ...firmware import qemu as fwqemu
        from ...firmware.build import replay_image

        elf = replay_image(artifact, target=platform.target.name, board=platform.board.name)
        return trace_of_records(fwqemu.replay(elf, artifact, board=platform.board.name, Y=Y, R=R, S=None))

    def one_step(
        self, artifact: Any, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, trace: Any, *, engine: str | None
    ) -> tuple[OneStepVerdict, ...]:
        """A trace of the C (or its model) bit for bit against the float32 model and within the solver's tolerance
        of the float64 algorithm run for the same iterations; a float64 trace bit for bit against the float64
        algorithm."""
        c_trace = engine in ("model", "native", "qemu") or (engine is None and trace_numeric(trace) == "float32")
        if c_trace:
            exact = one_step_check(artifact, Y, R, trace, Float32(), exact=True)
            near = one_step_check(artifact, Y, R, trace, Arith(), exact=False)
            return (OneStepVerdict(AGAINST_MODEL, exact), OneStepVerdict(AGAINST_FLOAT64, near))
        return (OneStepVerdict("the float64 algorithm from its own state",
                               one_step_check(artifact, Y, R, trace, Arith(), exact=True)),)  # fmt: skip

    def trace_text(self, artifact: Any, trace: Any, t: np.ndarray | None = None, *, engine: str | None = None) -> str:
        return format_trace(trace, t, numeric="float64" if engine == "reference" else "float32")

    def read_trace(self, path: str | Path, artifact: Any) -> Any:
        return read_trace(path, artifact)

    def records_trace(self, artifact: Any, records: np.ndarray) -> Any:
        return trace_of_records(records)

    # -- the closed loop (gainlink.laws.hooks.LoopHooks) ------------------------------------------------------

    def integrator_columns(self, artifact: Any) -> slice | None:
        return slice(artifact.n, artifact.n + artifact.q)

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        from ..lq.run import design_model

        return design_model(artifact, state=state, deviation=deviation)

    def describe(self, artifact: Any) -> dict:
        from ..lq.run import describe

        return describe(artifact) | super().describe(artifact)

    def simulate(self, artifact: Any, *, steps: int, x0: Any = None, reference: Any = None, noise_std: float = 0.0,
                 seed: int = 0, signals: Any = None) -> Any:  # fmt: skip
        """The float64 algorithm around the artifact's own discrete plant (:func:`.run.simulate`)."""
        from .run import simulate

        if signals is not None and np.size(signals):
            raise DataError(f"artifact {artifact.name} is not scheduled: it takes no external scheduling signals")
        return simulate(artifact, steps=steps, x0=x0, reference=reference, noise_std=noise_std, seed=seed)

    def run_report(self, artifact: Any, trace: Any, *, ran: str | None, design_model: bool) -> dict:
        from .run import iterations

        return iterations(artifact, trace, ran=ran)

    def report_lines(self, metrics: Mapping[str, Any]) -> list[str]:
        from .run import summary_lines

        return summary_lines(metrics)

    def pil_check(self, artifact: Any, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray,
                  trace: Any, twin_u: np.ndarray | None, design_model: bool, check_plant: Any) -> dict:  # fmt: skip
        from .run import pil_check

        return pil_check(artifact, records, Y=Y, R=R)

    def pil_lines(self, summary: Mapping[str, Any]) -> list[str]:
        from .run import pil_lines

        return pil_lines(summary)

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        from ..lq.run import image_stream

        return image_stream(artifact, target=target, board=board)

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from ..lq.run import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)

    def cost_bound(self, artifact: Any, elf: Any, *, target: str, board: str) -> dict | None:
        """The step's bound at the cap on ``elf`` (:func:`.cost.bound_block`: proved per core, or why not)."""
        from .cost import bound_block

        return bound_block(artifact, Path(elf), board=board, core=target)

    # -- what the commands print --------------------------------------------------------------------------------

    def design_lines(self, result: DesignResult, path: Path) -> list[str]:
        """The observer-based law's lines (the LQ law the MPC reduces to), then the MPC's own."""
        a = result.artifact
        b = a["mpc"]
        lines = LqLaw().design_lines(result, path)
        return lines[:-1] + [
            f"  MPC: horizon {b['horizon']}, ADMM cap {b['max_iter']} iterations, tol {b['tol']:g} of each signal's "
            f"scale, rho {b['rho']:.4g} (inputs), rho_state {b['rho_state']:.4g} (boxes), "
            f"{len(b['boxes'])} soft box(es); with no constraint active its optimum is the LQ law above",
            lines[-1],
        ]

    def design_json(self, result: DesignResult, path: Path) -> dict:
        b = result.artifact["mpc"]
        keys = ("horizon", "max_iter", "tol", "rho", "rho_state", "box_weight", "boxes")
        return LqLaw().design_json(result, path) | {"mpc": {k: b[k] for k in keys}}

    def design_plots(self, artifact: Any) -> tuple[dict[str, bytes], str | None]:
        return {}, "not drawn for an MPC law (its loop is linear only while no constraint is active)"

    def open_loop_note(self, artifact: Any) -> str:
        return ("the MPC law warm-starts its solver from its own previous solution: replays compared open loop "
                "drift apart once an iteration count differs; the one-step check is the verdict")  # fmt: skip


# -- trace files ------------------------------------------------------------------------------------------------


def trace_numeric(trace: MpcTrace) -> str:
    return getattr(trace, "numeric", "float32")


def format_trace(trace: MpcTrace, t: np.ndarray | None = None, *, numeric: str) -> str:
    """The replay CSV of an MPC trace: ``# numeric=...``, then per step the commands, saturation bits, flags,
    iterations and the law's whole state (round-trip floats)."""
    N, m = trace.u.shape
    header = (["t"] if t is not None else []) + [f"u{i}" for i in range(m)] + ["sat", "flags", "iters"]
    header += [f"s{i}" for i in range(trace.state.shape[1])]
    out = io.StringIO()
    out.write(f"# numeric={numeric}\n" + ",".join(header) + "\n")
    num = lambda v: repr(float(v)) if math.isfinite(v) else str(float(v))  # noqa: E731
    for k in range(N):
        cells = ([num(t[k])] if t is not None else []) + [num(v) for v in trace.u[k]]
        cells += [str(int(trace.sat[k])), str(int(trace.flags[k])), str(int(trace.iterations[k]))]
        out.write(",".join(cells + [num(v) for v in trace.state[k]]) + "\n")
    return out.getvalue()


class _NamedTrace(MpcTrace):
    numeric: str = "float32"


def read_trace(path: str | Path, artifact: Any) -> MpcTrace:
    """An MPC replay CSV back into a trace (DataError naming the file when it is not one of this artifact)."""
    from ...fileio import read_user_file

    text = read_user_file(Path(path), what="comparison file", error=DataError)
    lines = text.splitlines()
    numeric = "float32"
    if lines and lines[0].startswith("# numeric="):
        numeric, lines = lines[0].split("=", 1)[1].strip(), lines[1:]
    a = artifact
    width = len(MpcLoop(a, Arith()).state())
    try:
        head = lines[0].split(",")
        rows = np.array([[float(c) for c in line.split(",")] for line in lines[1:] if line.strip()])
    except (IndexError, ValueError):
        raise DataError(f"comparison file {path} is not an MPC replay trace") from None
    off = 1 if head and head[0] == "t" else 0
    if rows.ndim != 2 or rows.shape[1] != off + a.m + 3 + width:
        raise DataError(f"comparison file {path} is not an MPC replay trace of artifact {a.name}")
    tr = _NamedTrace(u=rows[:, off : off + a.m], sat=rows[:, off + a.m].astype(np.int64),
                     flags=rows[:, off + a.m + 1].astype(np.int64), iterations=rows[:, off + a.m + 2].astype(np.int64),
                     state=rows[:, off + a.m + 3 :])  # fmt: skip
    object.__setattr__(tr, "numeric", numeric)
    return tr
