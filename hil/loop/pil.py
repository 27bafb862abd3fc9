"""Processor-in-the-loop: a Cortex-M image in QEMU closes the loop with a plant simulated in Python, through the one
closed loop (:mod:`.closed_loop`) with the image as its endpoint (:class:`~.endpoints.OverFifos`).

Samples travel through two FIFOs that the image opens with semihosting (``gl_in.bin``, ``gl_out.bin``), one record
per step: one image for every law (``firmware/ports/cortex-m/main.c``, the stream ``GLI2``/``GLO2``: in ``{tag, y,
r, s}``, out the law's record, :mod:`gainlink.shipping.records`), which the law reads (``Law.image_stream``: its
step's flags, words and sigma). Python opens its ends read-write, so no open blocks, and every read waits with a
deadline while checking that QEMU is still alive. The twins are computed after the run; the law checks its image's
records (``Law.pil_check``: a fixed-point law's integer model and certified bounds, a scheduled law's float32 model
and host C, bit for bit).
"""

from __future__ import annotations

import logging
import os
import select
import struct
import subprocess
import tempfile
from abc import ABC, abstractmethod
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import FirmwareError, PeerTimeoutError, PlantError
from gainlink.firmware import qemu as fwqemu
from gainlink.firmware.cost import StepCost, counter_plugin, read_count
from gainlink.firmware.targets import resolve_cortex_m
from gainlink.laws import flags, law_of
from gainlink.proof.sampled_plant import SampledPlant
from gainlink.proof.twin import TwinComparison, TwinTrace, run_twin, twin_comparison
from gainlink.proof.twin_plot import twin_difference_figure
from gainlink.shipping.artifact import Artifact

from .closed_loop import ClosedLoop
from .endpoints import OverFifos
from .faults import FaultInjector
from .plan import Plan, Recorder
from .twins import Twins, TwinStart, twin_start
from .twins import model_twin as model_twin_after

log = logging.getLogger(__name__)


class DiscretePlant(ABC):
    """A plant sampled at the controller's period: outputs now, then advance one period under ``u``."""

    @abstractmethod
    def outputs(self) -> np.ndarray:
        """Measurement for the current sample."""

    @abstractmethod
    def advance(self, *, u: np.ndarray) -> None:
        """Apply ``u`` for one sample period."""

    @property
    @abstractmethod
    def state(self) -> np.ndarray:
        """The current plant state."""


class ArtifactPlant(DiscretePlant):
    """The artifact's own discrete model about its operating point, with absolute signals:
    ``x+ = Ad x + Bd (u - u_op)``, ``y = y_op + Cd x + Dd (u_prev - u_op)`` (``x`` a deviation).

    The feed-through acts on the previous command: the controller computes ``u`` from ``y``, so ``y``
    cannot depend on the same sample's ``u`` without an algebraic loop.
    """

    def __init__(self, artifact: Artifact, *, x0: np.ndarray) -> None:
        self.model = SampledPlant.from_artifact(artifact, x0=x0)  # x0 is in the design's coordinates
        names = tuple(artifact.signals["states"])
        self.names = names if len(names) == artifact.n else ()  # its states by the artifact's names

    def outputs(self) -> np.ndarray:
        return self.model.outputs()

    def advance(self, *, u: np.ndarray) -> None:
        self.model.advance(u)

    @property
    def state(self) -> np.ndarray:
        return self.model.state


class HilPlant(DiscretePlant):
    """A plant from ``gainlink.hil``'s registry (e.g. ``cart_pendulum``), advanced by ``Ts`` per sample."""

    def __init__(self, name: str, *, artifact: Artifact, x0: np.ndarray | None = None) -> None:
        from ..plants.base import check_dimensions
        from ..plants.config import plant_from_config

        self.plant = plant_from_config({"kind": name}, artifact=artifact)
        check_dimensions(self.plant, m=artifact.m, p=artifact.p, artifact=artifact.name)
        names = tuple(self.plant.state_names)
        if x0 is not None and len(x0) != len(names):
            raise PlantError(f"--x0 needs {len(names)} values for plant {name} ({', '.join(names)})")
        self.plant.reset(initial={} if x0 is None else dict(zip(names, (float(v) for v in x0))))
        self.Ts = artifact.Ts

    def outputs(self) -> np.ndarray:
        return np.asarray(self.plant.outputs(), dtype=float)

    def advance(self, *, u: np.ndarray) -> None:
        self.plant.advance(u=np.asarray(u, dtype=float), dt=self.Ts)

    @property
    def state(self) -> np.ndarray:
        return np.asarray(self.plant.state(), dtype=float)


def make_plant(name: str, *, artifact: Artifact, x0: np.ndarray | None = None) -> DiscretePlant:
    """``artifact`` (alias ``linear``): the artifact's discrete model (a scheduled artifact's: its points' models
    interpolated at a moving sigma, the ``lpv_model`` plant, ``x0`` absolute); any other name: a
    ``gainlink.hil`` plant."""
    if name in ("artifact", "linear"):
        name = law_of(artifact).own_plant
    if name in ("artifact", "linear"):
        start = np.full(artifact.n, 0.1) if x0 is None else np.asarray(x0, dtype=float)
        if start.shape != (artifact.n,):
            raise PlantError(f"--x0 needs {artifact.n} values for artifact {artifact.name}")
        return ArtifactPlant(artifact, x0=start)
    return HilPlant(name, artifact=artifact, x0=x0)


@dataclass(frozen=True)
class PilResult:
    """A closed-loop PIL run: per step the measurement, the image's command, flags and sigma, and timing; the
    twins; the law's own checks of the image's records."""

    law: str  # the law that ran (its label)
    y: np.ndarray  # (N, p)
    u: np.ndarray  # (N, m) float32 commands from the firmware
    flags: np.ndarray  # (N,) status flags (gainlink.laws.flags)
    saturated: np.ndarray  # (N, m) bool
    sigma: np.ndarray  # (N,) the sigma the law used (NaN for a law without one)
    plant_state: np.ndarray  # (N + 1, plant states)
    round_trip_us: np.ndarray  # (N,)
    steps_per_second: float
    records: np.ndarray  # (N,) the image's output records as they came (Law.image_stream's dout)
    checks: dict  # the law's own blocks (Law.pil_check): e.g. "fixed_point", "scheduled"
    twin: TwinTrace | None = None  # the float64 twin's run (gainlink.proof.twin), when one ran
    comparison: TwinComparison | None = None  # the run against its twin
    model_twin: TwinTrace | None = None  # the law around the design's own model, when one ran
    model_twin_start: str = ""  # where the model twin started
    reference: np.ndarray | None = None  # (N, q) the references the run tracked
    signals: np.ndarray | None = None  # (N, e) the external scheduling signals
    cost: StepCost | None = None  # the instructions of the law's step in this run (QEMU's counter)
    cost_symbol: str = ""  # the step function the count covers
    cost_bound: dict | None = None  # the law's bound on that count for this image (Law.cost_bound), if it states one

    def summary(self) -> dict:
        """Counts, timing, the comparison with the twin and the law's checks, JSON-ready."""
        out = {
            "law": self.law,
            "steps": int(self.u.shape[0]),
            "saturated_steps": int(self.saturated.any(axis=1).sum()),
            "faults": int(np.count_nonzero(self.flags & flags.FAULT)),
            "steps_per_second": round(self.steps_per_second, 1),
            "round_trip_us_p50": round(float(np.median(self.round_trip_us)), 1),
            "round_trip_us_p99": round(float(np.percentile(self.round_trip_us, 99)), 1),
            "final_output": [float(v) for v in self.y[-1]],
        }
        if self.cost is not None:
            out["instructions_per_step"] = instructions_block(self.cost, symbol=self.cost_symbol)
            if self.cost_bound is not None:
                out["instructions_per_step"]["bound"] = self.cost_bound
        if self.comparison is not None:
            out["twin"] = self.comparison.to_dict()
        for name, block in self.checks.items():
            out[name] = block.to_dict()
        return out


def twin_figure(result: PilResult, artifact: Artifact, *, title: str | None = None) -> Any:
    """The run minus its float64 twin per output and input, as the HIL report's ``twin.png`` shows it
    (:func:`gainlink.twin_plot.twin_difference_figure`); refused (non-finite) samples are marked.

    Raises
    ------
    PlantError
        The run had no twin (``run_pil(..., twin=None)``).
    """
    if result.twin is None:
        raise PlantError("this PIL run had no twin to plot against (run_pil(twin=...))")
    sig = artifact.signals
    return twin_difference_figure(
        np.arange(result.u.shape[0]) * artifact.Ts,
        y=result.y,
        twin_y=result.twin.y,
        u=result.u.astype(float),
        twin_u=result.twin.u,
        outputs=list(sig["outputs"]),
        inputs=list(sig["inputs"]),
        title=title or f"PIL {artifact.name}",
        marked=(result.flags & flags.FAULT) != 0,
        marked_label="sample refused (non-finite)",
        units=sig.get("units"),
        time_unit=artifact.unit("time"),
    )


INSTRUCTIONS_NOTE = (
    "guest instructions QEMU executed (TCG plugin) from the entry of the law's step function to its return, callees "
    "included, as the cost benchmarks count them; instructions, not cycles"
)


def instructions_block(cost: StepCost, *, symbol: str) -> dict:
    """``pil.json``'s ``instructions_per_step``: the mean and the worst over the run's steps, the part inside the step's
    own symbol, and what the figure covers."""
    return {
        "symbol": symbol,
        "mean": round(cost.per_step, 1),
        "worst": int(cost.dearest),
        "fewest": int(cost.cheapest),
        "own_mean": round(cost.own_per_step, 1),
        "calls": int(cost.calls),
        "covers": INSTRUCTIONS_NOTE,
    }


def _read_exact(fd: int, size: int, *, proc: subprocess.Popen, deadline_s: float) -> bytes:
    buf = b""
    while len(buf) < size:
        ready, _, _ = select.select([fd], [], [], deadline_s)
        if not ready:
            if proc.poll() is not None:
                raise FirmwareError(
                    f"firmware in QEMU stopped: {fwqemu.EXIT_CODES.get(proc.returncode, proc.returncode)}"
                )
            raise PeerTimeoutError(f"firmware in QEMU sent nothing for {deadline_s} s")
        buf += os.read(fd, size - len(buf))
    return buf


def run_pil(
    artifact: Artifact,
    *,
    plant: DiscretePlant,
    steps: int,
    reference: np.ndarray | None = None,
    signals: np.ndarray | None = None,
    target: str | None = None,
    board: str | None = None,
    watchdog_periods: int = 10,
    deadline_s: float = 10.0,
    twin: DiscretePlant | None = None,
    model_twin: bool = True,
    check_plant: DiscretePlant | None = None,
) -> PilResult:
    """Close the loop: the law's image in QEMU, ``plant`` in Python, one FIFO round trip per sample.

    Parameters
    ----------
    artifact : Artifact
        Artifact whose image runs (built and cached by sha256; its law's: ``Law.image_stream``).
    plant : DiscretePlant
        The plant; its outputs are sampled each period (a plant with a ``schedule(s)`` method hears the external
        scheduling signals before each sample).
    steps : int
        Number of samples.
    reference : ndarray, optional
        (q,) constant absolute reference or (steps, q) sequence; by default the law's trim where the run starts
        (``Law.r_op``: the tracked outputs at the operating point).
    signals : ndarray, optional
        (steps, e) external scheduling signals; required when the law has any (``Law.externals``).
    target : str, optional
        The core whose image runs: ``cortex-m0``, ``cortex-m3``, ``cortex-m4`` (default), ``cortex-m7``,
        ``cortex-m33`` or ``cortex-m55`` (see :mod:`gainlink.firmware.targets`).
    board : str, optional
        Its QEMU machine (default: the target's; a board alone implies its core).
    deadline_s : float
        How long to wait for one answer before declaring the firmware silent.
    twin : DiscretePlant, optional
        A second instance of the plant, in the same initial state: the float64 twin of the loop
        (:mod:`gainlink.proof.twin`) runs on it, after the run, and the result compares the two.
    model_twin : bool
        Run the law around the design's own model (``Law.design_model``) started where the plant starts.
    check_plant : DiscretePlant, optional
        A further instance of the plant in the same initial state, for a law whose check closes a loop of its own
        (a fixed-point law: the float64 law with its quantised coefficients, which its certified rounding bound
        compares with).

    Returns
    -------
    PilResult
        ``checks`` holds the law's own checks of its image: for a fixed-point artifact ``fixed_point`` (the image
        bit for bit the model on the samples it received, the deviation from the quantised twin beside the
        certified bound), for a scheduled one ``scheduled`` (every record the float32 model's and the host C's).
    """
    a, law = artifact, law_of(artifact)
    if steps < 1:
        raise PlantError("--steps must be at least 1")
    S = _signals(a, law, signals, steps)
    platform = resolve_cortex_m(target, board)
    stream = law.image_stream(a, target=platform.target.name, board=platform.board.name)
    sampled = _Sampled(plant, Ts=a.Ts)
    plan = _plan(a, law, sampled, steps=steps, reference=reference, S=S)
    start = _twin_start(plant, sigma=plan.sigma0) if model_twin else None
    rec = Recorder(plan, artifact=a, plant=sampled)
    endpoint, outcome, cost = _closed_loop_in_qemu(a, law, stream, board=platform.board.name, plan=plan, plant=sampled,
                                                   recorder=rec, steps=steps, watchdog_periods=watchdog_periods,
                                                   deadline_s=deadline_s)  # fmt: skip
    bound = law.cost_bound(a, stream.elf, target=platform.target.name, board=platform.board.name)
    tw = None if twin is None else _twin_after(a, law, twin, plan, steps)  # off the per-sample path
    mt, note = (None, "off") if start is None else model_twin_after(law, a, start=start, plan=plan, steps=steps)
    return _result(a, law, rec, endpoint, plan=plan, wall_s=outcome.wall_s, twins=(tw, mt, note),
                   design_model=isinstance(plant, ArtifactPlant), check_plant=check_plant,
                   final_state=sampled.state(), cost=(cost, stream.symbol, bound))  # fmt: skip


def _closed_loop_in_qemu(
    a: Artifact,
    law: Any,
    stream: Any,
    *,
    board: str,
    plan: Any,
    plant: _Sampled,
    recorder: Recorder,
    steps: int,
    watchdog_periods: int,
    deadline_s: float,
) -> tuple:
    """The run itself: the image in QEMU over its FIFOs, the one closed loop around it, the step's instruction
    count read when the image has exited: ``(endpoint, outcome, count)``."""
    with _qemu_fifos(stream.elf, board=board, steps=steps, symbol=stream.symbol) as qemu:
        proc, fin, fout, count = qemu
        _open_stream(proc, fin, fout, stream, steps=steps, watchdog_periods=watchdog_periods, deadline_s=deadline_s)
        endpoint = OverFifos(stream, link=(proc, fin, fout), recorder=recorder, deadline_s=deadline_s, steps=steps,
                             safe_command=law.safe_command(a), read=_read_exact)  # fmt: skip
        loop = ClosedLoop(plan=plan, plant=plant, endpoint=endpoint, injector=FaultInjector((), Ts=a.Ts), Ts=a.Ts,
                          record_state=True)  # fmt: skip
        outcome = loop.run(None)
        _await_exit(proc, deadline_s=deadline_s)
        return endpoint, outcome, read_count(count)


class _Sampled:
    """A :class:`DiscretePlant` as the closed loop steps a plant (``advance(u, dt)``, ``state()``, the names its
    record needs, and its ``schedule(s)`` when it follows external signals)."""

    def __init__(self, plant: DiscretePlant, *, Ts: float) -> None:
        self.plant, self.Ts = plant, Ts
        self.state_names = tuple(f"x{i}" for i in range(np.size(plant.state)))
        follow = getattr(getattr(plant, "plant", plant), "schedule", None)
        if follow is not None:
            self.schedule = follow

    def outputs(self) -> np.ndarray:
        return self.plant.outputs()

    def advance(self, *, u: np.ndarray, dt: float) -> None:
        self.plant.advance(u=u)

    def state(self) -> np.ndarray:
        return np.asarray(self.plant.state, dtype=float)


def _signals(a: Artifact, law, signals: np.ndarray | None, steps: int) -> np.ndarray:
    """The external scheduling signals per step (steps, e), checked against the law's."""
    e = len(law.externals(a))
    S = np.zeros((steps, e)) if signals is None else np.asarray(signals, dtype=float).reshape(steps, -1)
    if S.shape[1] != e:
        raise PlantError(f"artifact {a.name} needs {e} external scheduling signal(s) per step, got {S.shape[1]}")
    return S


def _plan(a: Artifact, law, plant: _Sampled, *, steps: int, reference, S: np.ndarray) -> Plan:
    """The run's plan: no noise, no disturbance, no fault; the reference given or the law's trim where it starts."""
    follow = getattr(plant, "schedule", None)
    if follow is not None:
        follow(S[0])
    sigma0 = law.sigma_of(a, plant.outputs(), S[0])
    r = law.r_op(a, sigma=sigma0) if reference is None else np.asarray(reference, dtype=float)
    R = np.array(np.broadcast_to(r, (steps, a.q)), dtype=float)
    return Plan(N=steps, t=np.arange(steps) * a.Ts, R=R, noise=np.zeros((steps, a.p)), D=np.zeros((steps, a.m)),
                S=S, sigma0=sigma0, silent_at=None, crash_at=None, period_s=a.Ts, realtime=False)  # fmt: skip


def _twin_start(plant: DiscretePlant, *, sigma: float) -> TwinStart:
    """Where the plant starts, for the model twin: a ``gainlink.hil`` plant's state by name, or the artifact's own
    model's state (a deviation, in the design's coordinates)."""
    inner = getattr(plant, "plant", None)
    if inner is not None:
        return twin_start(inner, sigma=sigma)
    names = plant.names if isinstance(plant, ArtifactPlant) else ()
    return TwinStart(dict(zip(names, np.asarray(plant.state, dtype=float))), True, float(sigma))


def _twin_after(a: Artifact, law, plant: DiscretePlant, plan: Plan, steps: int) -> TwinTrace:
    """The float64 law closing the loop on ``plant`` (in the run's initial state) for the run's samples."""
    follow = getattr(getattr(plant, "plant", plant), "schedule", None)
    return run_twin(law.reference(a), outputs=plant.outputs, advance=lambda u: plant.advance(u=u), noise=plan.noise,
                    R=plan.R, D=plan.D, S=plan.S, steps=steps, on_signals=follow)  # fmt: skip


def _result(a: Artifact, law, rec: Recorder, endpoint, *, plan: Plan, wall_s: float, twins: tuple,
            design_model: bool, check_plant, final_state: np.ndarray, cost: tuple) -> PilResult:  # fmt: skip
    """The PIL result from the run's record, its twins, the law's checks of the image's records and the count of its
    step's instructions (``cost``: the count, the symbol it covers and the law's bound on it)."""
    twin_trace, model, note = twins
    steps = plan.N
    trace = rec.trace(steps, law=law, artifact=a, twins=Twins(twin_trace, model, note, {}))
    comparison = None
    if twin_trace is not None:
        comparison = twin_comparison(t=plan.t, y=trace.y, u=trace.u, r=plan.R, twin_y=twin_trace.y,
                                     twin_u=twin_trace.u, artifact=a)  # fmt: skip
    checks = law.pil_check(a, endpoint.records, Y=trace.y, R=plan.R, S=plan.S, trace=trace,
                           twin_u=None if twin_trace is None else twin_trace.u, design_model=design_model,
                           check_plant=check_plant)  # fmt: skip
    return PilResult(
        law=law.label,
        y=trace.y,
        u=trace.u.astype(np.float32),
        flags=trace.flags,
        saturated=trace.sat,
        sigma=trace.sigma,
        plant_state=np.vstack([rec.X[:steps], final_state]),
        round_trip_us=trace.latency_ns / 1e3,
        steps_per_second=steps / wall_s if wall_s > 0 else float("inf"),
        records=endpoint.records,
        checks=checks,
        twin=twin_trace,
        comparison=comparison,
        model_twin=model,
        model_twin_start=note,
        reference=plan.R,
        signals=plan.S,
        cost=cost[0],
        cost_symbol=cost[1],
        cost_bound=cost[2],
    )


@contextmanager
def _qemu_fifos(elf: Path, *, board: str, steps: int, symbol: str):
    """QEMU running ``elf`` with its semihosting files gl_in.bin/gl_out.bin as FIFOs, counting the instructions of
    every call of ``symbol`` (:func:`gainlink.firmware.cost.counter_plugin`): (process, in fd, out fd, the file the
    count is in once QEMU exited)."""
    with tempfile.TemporaryDirectory(prefix="gainlink-pil-") as tmp:
        work = Path(tmp)
        os.mkfifo(work / "gl_in.bin")
        os.mkfifo(work / "gl_out.bin")
        count = work / "count.txt"
        plugin = counter_plugin(elf, symbol=symbol, out=count)
        fin = os.open(work / "gl_in.bin", os.O_RDWR)
        fout = os.open(work / "gl_out.bin", os.O_RDWR)
        cmd = ["timeout", "-k", "2", str(60 + steps / 1000)] + fwqemu.qemu_command(
            elf, board=board, serial=f"file:{work / 'uart.log'}", plugin=plugin
        )
        proc = subprocess.Popen(
            cmd, cwd=work, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        try:
            yield proc, fin, fout, count
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            os.close(fin)
            os.close(fout)


def _open_stream(proc: subprocess.Popen, fin: int, fout: int, stream, *, steps: int, watchdog_periods: int,
                 deadline_s: float) -> None:  # fmt: skip
    """Send the stream header (steps, one sample per record, the watchdog's periods) and check the image's answer:
    the magic (``GLO2``), the count, the law it runs and its dimensions (``stream.header``:
    :func:`gainlink.firmware.qemu.output_header`)."""
    os.write(fin, struct.pack("<4I", stream.in_magic, steps, 1, watchdog_periods if stream.watchdog else 0))
    header = _read_exact(fout, 32, proc=proc, deadline_s=deadline_s)
    got, count, *shape = struct.unpack("<8I", header)
    if got != stream.out_magic or count != steps or tuple(shape) != tuple(stream.header):
        raise FirmwareError("firmware answered with a bad stream header (image built for another artifact or law?)")


def _await_exit(proc: subprocess.Popen, *, deadline_s: float) -> None:
    """The firmware exits by itself after the last sample, with status 0."""
    try:
        proc.wait(timeout=deadline_s)
    except subprocess.TimeoutExpired:
        raise FirmwareError("firmware in QEMU did not exit after the last sample") from None
    if proc.returncode != 0:
        raise FirmwareError(f"firmware in QEMU failed: {fwqemu.EXIT_CODES.get(proc.returncode, proc.returncode)}")
