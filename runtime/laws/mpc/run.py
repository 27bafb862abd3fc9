"""What a closed loop (:mod:`gainlink.hil.loop`) asks of the MPC law beyond its step: a closed-loop simulation of
its float64 algorithm, the solver's iterations in a run's report (from the bit-exact model replayed on the samples
the controller received: the C's own count when the run is bit for bit), and the summary's line on them."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import flags
from .arith import Arith
from .step import MpcLoop


def simulate(artifact: Any, *, steps: int, x0: Any, reference: Any, noise_std: float, seed: int) -> Any:
    """The float64 algorithm around the artifact's own discrete plant (:func:`gainlink.proof.simulation
    .simulate_linear`'s conventions: ``x0`` a deviation, ``reference`` absolute)."""
    from ...errors import DataError
    from ...proof.sampled_plant import SampledPlant
    from ...proof.simulation import closed_loop
    from .controllers import MpcController

    a = artifact
    if steps < 1:
        raise DataError("steps must be at least 1")
    r = a.r_op if reference is None else np.asarray(reference, float).reshape(a.q)
    plant = SampledPlant.from_artifact(a, x0=x0)
    noise = noise_std * np.random.default_rng(seed).standard_normal((steps, a.p))
    ctl = MpcController(MpcLoop(a, Arith()), {"kind": "reference (the MPC algorithm in float64)"})
    return closed_loop(ctl, plant, Ts=a.Ts, m=a.m, R=np.tile(r, (steps, 1)), noise=noise, S=np.zeros((steps, 0)))


def iterations(artifact: Any, trace: Any, *, ran: str | None) -> dict:
    """The ``mpc`` block of a run's report: the solver's iterations per solved step (mean, worst), the steps the
    cap stopped (``capped_steps``: the projected first move was applied) and the cap, counted by the law that ran on
    the samples it received, in turn: the host C's records (bit for bit the float32 model of every build of the C,
    tests/test_mpc.py; one C call for the run), or the float64 algorithm for a reference run; and the answers'
    CAPPED bits as they arrived (``capped_steps_read``; every link carries them) against that count's, step by step
    (``capped_read_is_the_models``)."""
    from ...firmware.host import HostLaw
    from .controllers import trace_of_records

    a = artifact
    Y = np.where(np.asarray(trace.nan_sent)[:, None], np.nan, trace.y)
    R = trace.r
    if ran is None:
        run = MpcLoop(a, Arith()).run(Y, R)
    else:
        run = trace_of_records(HostLaw(a).run(Y.astype(np.float32), R.astype(np.float32)))
    solved = run.iterations[~run.fault]
    by = "the float64 algorithm" if ran is None else "the host C's records, on the samples the controller received"
    block = {"horizon": int(a.mpc.horizon), "cap": int(a.mpc.max_iter), "solved_steps": int(solved.size),
             "iterations_mean": float(solved.mean()) if solved.size else None,
             "iterations_max": int(solved.max()) if solved.size else None,
             "capped_steps": int(np.count_nonzero(run.flags & flags.CAPPED)), "counted_by": by}  # fmt: skip
    return {"mpc": block | _capped_on_the_wire(trace, run.flags)}


def _capped_on_the_wire(trace: Any, model_flags: np.ndarray) -> dict:
    """The capped steps the commands that arrived said they were (the CAPPED bit every link carries: wire format
    3), and whether each answered step's bit is the model's on the same sample."""
    got = np.asarray(trace.got, dtype=bool)
    wire = np.asarray(trace.flags)[got] & flags.CAPPED
    return {"capped_steps_read": int(np.count_nonzero(wire)),
            "capped_read_is_the_models": bool(np.array_equal(wire, model_flags[got] & flags.CAPPED))}  # fmt: skip


def summary_lines(metrics: Mapping[str, Any]) -> list[str]:
    """The run summary's line on the solver (nothing without an ``mpc`` block)."""
    b = metrics.get("mpc")
    if not b or not b["solved_steps"]:
        return []
    lines = [f"  MPC horizon {b['horizon']}: {b['iterations_mean']:.1f} iterations per step on average, "
             f"{b['iterations_max']} at worst (cap {b['cap']}); {b['capped_steps']} of {b['solved_steps']} steps "
             "stopped at the cap (the projected first move applied)"]  # fmt: skip
    if "capped_read_is_the_models" in b:
        agree = "as the model's" if b["capped_read_is_the_models"] else "DIFFERENT from the model's, step by step"
        lines.append(f"  {b['capped_steps_read']} answers said CAPPED on the link, {agree}")
    return lines


@dataclass(frozen=True)
class PilCheck:
    """The ``mpc`` block of a PIL run (:func:`pil_check`)."""

    block: dict

    def to_dict(self) -> dict:
        """JSON-ready."""
        return dict(self.block)


def pil_check(artifact: Any, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray) -> dict:
    """The ``mpc`` block of a PIL run: the image's records (command, flags, iterations and its whole state) checked
    one step at a time from the image's own state against the float32 model with the image's iteration count, on the
    float32 samples it was sent, and the solver's iterations (mean, worst, steps the cap stopped)."""
    from .arith import Float32
    from .controllers import trace_of_records
    from .onestep import one_step_check

    trace = trace_of_records(records)
    Y32, R32 = (np.asarray(v, dtype=np.float32).astype(np.float64) for v in (Y, R))
    check = one_step_check(artifact, Y32, R32, trace, Float32(), exact=True)
    solved = trace.iterations[~trace.fault]
    return {"mpc": PilCheck({"horizon": int(artifact.mpc.horizon), "cap": int(artifact.mpc.max_iter),
                    "bit_exact": check.passed,
                    "first_difference": None if check.passed else check.first_failure.describe("the image"),
                    "solved_steps": int(solved.size),
                    "iterations_mean": float(solved.mean()) if solved.size else None,
                    "iterations_max": int(solved.max()) if solved.size else None,
                    "capped_steps": int(np.count_nonzero(trace.flags & flags.CAPPED)),
                    "counted_by": "the image's own records"})}  # fmt: skip


def pil_lines(summary: Mapping[str, Any]) -> list[str]:
    """The PIL summary's lines on the solver and the image's check."""
    b = summary.get("mpc")
    if not b:
        return []
    exact = "bit for bit its float32 model" if b["bit_exact"] else f"DIFFERS: {b['first_difference']}"
    return [f"  MPC image: {exact}, step by step from its own state", *summary_lines(summary)]
