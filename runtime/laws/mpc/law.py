"""The MPC law in float32 (docs/design.md, "MPC (the fourth law)"): its design, its float64 model of the algorithm,
the bit-exact float32 model of its C, the host C through ctypes, its replay engines, one-step checks and trace files.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import DataError
from .. import flags
from ..base import Capabilities, Controller, Law, OneStepVerdict, Step
from ..lq import LqLaw
from .arith import Arith, Float32
from .step import MpcLoop, MpcTrace

if TYPE_CHECKING:
    from ...proof.sampled_plant import SampledPlant
    from ...spec import PlantSpec
    from ...synthesis.pipeline import DesignResult

AGAINST_MODEL = "the C's float32 arithmetic, bit for bit, from its own state at each step (its iteration count too)"
AGAINST_FLOAT64 = ("the float64 algorithm from the same state with the same iteration count, within the solver's own "
                   "tolerance (measured, not a proved float32 bound)")  # fmt: skip
#: The cells the MPC law cannot do yet, each with its reason (refused in one generated line).
CANNOT = {
    "fidelity": "its design records no float32 fidelity figure (a bound on the C against the float64 algorithm "
    "over any history is not derived for the ADMM); each step of a trace is checked instead: bit "
    "for bit its float32 model, within the solver's tolerance of the float64 algorithm (one_step)"
}


class MpcController:
    """An :class:`~.step.MpcLoop` as a :class:`Controller`."""

    def __init__(self, loop: MpcLoop, describe: dict) -> None:
        self.loop, self.describe = loop, describe
        self.last = None

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample (``s`` unused: the MPC law is not scheduled)."""
        res = self.last = self.loop.step(y, r)
        return Step(u=np.asarray(res.u, dtype=float), flags=res.flags, sat=res.sat)

    def reset(self) -> None:
        """Back to the start state."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """``xh, z`` and the warm start (:meth:`.step.MpcLoop.state`)."""
        return self.loop.state()


class MpcNative:
    """The host C's MPC law (:class:`~gainlink.firmware.host.HostLaw`) as a :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from ...firmware.host import HostLaw

        self.host = HostLaw(artifact, library=library)
        self.describe = {"kind": "firmware (host C MPC law, ctypes)", "library": str(self.host.library)}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample through ``gl_mpc_step``: its record's flags are the status flags."""
        rec = self.host.step(y, r)
        return Step(u=rec["u"].astype(float), flags=int(rec["flags"]), sat=int(rec["sat"]))

    def reset(self) -> None:
        """``gl_law_reset``."""
        self.host.reset()

    def state(self) -> np.ndarray:
        """The C's whole state as its last record carries it (``xh, z`` and the warm start)."""
        return np.asarray(self.host.last_record["state"], dtype=float)


def trace_of_records(rec: np.ndarray) -> MpcTrace:
    """The C's records (:func:`gainlink.shipping.records.layout` of the MPC law) as a trace."""
    return MpcTrace(u=rec["u"].astype(float), sat=rec["sat"].astype(np.int64), flags=rec["flags"].astype(np.int64),
                    iterations=rec["iters"].astype(np.int64), state=rec["state"].astype(float))  # fmt: skip


@dataclass(frozen=True)
class StepMismatch:
    """The first step where a trace left what it is checked against."""

    k: int
    what: str

    def describe(self, name: str) -> str:
        return f"step {self.k} of {name}: {self.what}"


@dataclass(frozen=True)
class MpcOneStep:
    """A one-step check of an MPC trace: ``steps`` checked, the first mismatch (None: every step held) and the
    largest deviation of the command relative to each input's limit span."""

    steps: int
    first_failure: StepMismatch | None
    max_rel_u: float

    @property
    def passed(self) -> bool:
        return self.first_failure is None

    def summary(self) -> str:
        verdict = "every step holds" if self.passed else "FAILED"
        return f"{self.steps} steps, {verdict}; max |du| {self.max_rel_u:.3g} of the limit span"


def one_step_check(artifact: Any, Y, R, trace: MpcTrace, ar: Arith, *, exact: bool) -> MpcOneStep:
    """Each step of ``trace`` from the trace's own previous state through the law in ``ar``, with the trace's own
    iteration count: ``exact`` asks for the same bits (commands, flags, saturation, iterations, state), else the
    command within the solver's tolerance."""
    a = artifact
    loop = MpcLoop(a, ar)
    span = a.u_max - a.u_min
    worst, eps = 0.0, a.mpc.eps["pu"]
    for k in range(len(Y)):
        if k:
            loop.set_state(trace.state[k - 1])
        it = int(trace.iterations[k]) or None
        res = loop.step(Y[k], R[k], iterations=None if exact else it)
        if res.fault:
            got = (trace.flags[k] & flags.FAULT) != 0 and np.array_equal(res.u, trace.u[k])
            if not got:
                return MpcOneStep(k + 1, StepMismatch(k, "a refused sample answered otherwise"), worst)
            continue
        worst = max(worst, float(np.max(np.abs(res.u - trace.u[k]) / span)))
        if exact:
            answer = (res.sat, res.flags, res.iterations)
            same = answer == (trace.sat[k], trace.flags[k], trace.iterations[k])
            if not (same and np.array_equal(res.u, trace.u[k]) and np.array_equal(loop.state(), trace.state[k])):
                what = f"not bit for bit (u {res.u}, iterations {res.iterations}; the trace {trace.u[k]}, "
                return MpcOneStep(k + 1, StepMismatch(k, what + f"{trace.iterations[k]})"), worst)
        elif np.any(np.abs(res.u - trace.u[k]) > eps):
            what = f"u {trace.u[k]} is {np.abs(res.u - trace.u[k])} from the float64 algorithm's {res.u}"
            return MpcOneStep(k + 1, StepMismatch(k, what + f", beyond the tolerance {eps}"), worst)
    return MpcOneStep(len(Y), None, worst)


class MpcLaw(Law):
    """Linear MPC on the observer-based law's estimate and integrators, solved by ADMM on cached Riccati gains."""

    structure = "mpc"
    numerics = ("float32",)

    @property
    def label(self) -> str:
        return "mpc-float32"

    @property
    def capabilities(self) -> Capabilities:
        return Capabilities(cannot=CANNOT)

    def reference(self, artifact: Any) -> Controller:
        return MpcController(MpcLoop(artifact, Arith()), {"kind": "reference (the MPC algorithm in float64)"})

    def model(self, artifact: Any) -> Controller:
        return MpcController(MpcLoop(artifact, Float32()), {"kind": "model (the MPC C's float32 arithmetic)"})

    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        return MpcNative(artifact, library=library)

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

    def integrators(self, artifact: Any, states: np.ndarray) -> np.ndarray | None:
        return np.asarray(states)[:, artifact.n : artifact.n + artifact.q]

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        from ..lq_run import design_model

        return design_model(artifact, state=state, deviation=deviation)

    def describe(self, artifact: Any) -> dict:
        from ..lq_run import describe

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
        from ..lq_run import image_stream

        return image_stream(artifact, target=target, board=board)

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        from ..lq_run import cost

        return cost(artifact, target=target, board=board, Y=Y, R=R, S=S)

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
