"""Processor-in-the-loop: a Cortex-M image in QEMU closes the loop with a plant simulated in Python.

Samples travel through two FIFOs that the image opens with semihosting (``gl_in.bin``, ``gl_out.bin``),
one record per step (see ``firmware/ports/cortex-m/main.c``). Python opens its ends read-write, so no
open blocks, and every read waits with a deadline while checking that QEMU is still alive. A fixed-point
artifact runs its integer image (``main_fixed.c``, the same stream; its records are
``gainlink.firmware.fixed``'s) and is checked by :mod:`.pil_fixed`; a scheduled artifact runs its scheduled image
(``main_sched.c``) through :mod:`.pil_scheduled`.
"""

from __future__ import annotations

import logging
import os
import select
import struct
import subprocess
import tempfile
import time
from abc import ABC, abstractmethod
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import FirmwareError, PeerTimeoutError, PlantError
from gainlink.firmware import fixed as fwfixed
from gainlink.firmware import qemu as fwqemu
from gainlink.firmware.build import replay_image
from gainlink.firmware.fixed import step_status
from gainlink.firmware.targets import resolve_cortex_m
from gainlink.laws import law_of
from gainlink.proof.sampled_plant import SampledPlant
from gainlink.proof.twin import TwinComparison, TwinTrace, run_twin, twin_comparison
from gainlink.proof.twin_plot import twin_difference_figure
from gainlink.shipping.artifact import Artifact
from gainlink.shipping.codegen_fixed import is_fixed

from .pil_fixed import FixedPilCheck, QuantisedTwin, fixed_pil_check

log = logging.getLogger(__name__)

FAULT_STATUS = -2  # GL_ERR_NANINF: the firmware refused a non-finite sample


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
        from ..plants import models  # noqa: F401 - registers the built-in models
        from ..plants.base import PLANTS, check_dimensions

        self.plant = PLANTS.create(name, {}, artifact=artifact)
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
    interpolated at a moving sigma, the ``scheduled_model`` plant, ``x0`` absolute); any other name: a
    ``gainlink.hil`` plant."""
    if name in ("artifact", "linear") and artifact.schedule is not None:
        name = "scheduled_model"
    if name in ("artifact", "linear"):
        start = np.full(artifact.n, 0.1) if x0 is None else np.asarray(x0, dtype=float)
        if start.shape != (artifact.n,):
            raise PlantError(f"--x0 needs {artifact.n} values for artifact {artifact.name}")
        return ArtifactPlant(artifact, x0=start)
    return HilPlant(name, artifact=artifact, x0=x0)


@dataclass(frozen=True)
class PilResult:
    """A closed-loop PIL run: per step the measurement, the firmware's command and status, and timing."""

    y: np.ndarray  # (N, p)
    u: np.ndarray  # (N, m) float32 commands from the firmware
    status: np.ndarray  # (N,)
    saturated: np.ndarray  # (N, m) bool
    plant_state: np.ndarray  # (N + 1, plant states)
    round_trip_us: np.ndarray  # (N,)
    steps_per_second: float
    twin: TwinTrace | None = None  # the float64 twin's run (gainlink.proof.twin), when one ran
    comparison: TwinComparison | None = None  # the run against its twin
    model_twin: TwinTrace | None = None  # the law around the artifact's own model (model_twin), when one ran
    reference: np.ndarray | None = None  # (N, q) the references the run tracked
    fixed_point: FixedPilCheck | None = None  # a fixed-point artifact's oracle (gainlink.hil.loop.pil_fixed)
    fixed_run: fwfixed.FixedRun | None = None  # a fixed-point image's records (words, estimate, flags) per step
    scheduled: Any = None  # a scheduled artifact's check (gainlink.hil.loop.pil_scheduled.ScheduledPilCheck)
    sigma: np.ndarray | None = None  # (N,) a scheduled image's sigma per step
    sigma_flags: np.ndarray | None = None  # (N,) its flags (held 1, clipped 2, rate-limited 4)

    def summary(self) -> dict:
        """Counts, timing and the comparison with the twin, JSON-ready."""
        out = {
            "steps": int(self.u.shape[0]),
            "saturated_steps": int(self.saturated.any(axis=1).sum()),
            "faults": int((self.status == FAULT_STATUS).sum()),
            "steps_per_second": round(self.steps_per_second, 1),
            "round_trip_us_p50": round(float(np.median(self.round_trip_us)), 1),
            "round_trip_us_p99": round(float(np.percentile(self.round_trip_us, 99)), 1),
            "final_output": [float(v) for v in self.y[-1]],
        }
        if self.comparison is not None:
            out["twin"] = self.comparison.to_dict()
        if self.fixed_point is not None:
            out["fixed_point"] = self.fixed_point.to_dict()
        if self.scheduled is not None:
            out["law"] = self.scheduled.law
            out["scheduled"] = self.scheduled.to_dict()
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
        marked=result.status == FAULT_STATUS,
        marked_label="sample refused (non-finite)",
        units=sig.get("units"),
        time_unit=artifact.unit("time"),
    )


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
    target: str | None = None,
    board: str | None = None,
    watchdog_periods: int = 10,
    deadline_s: float = 10.0,
    twin: DiscretePlant | None = None,
    model_twin: DiscretePlant | None = None,
    quantised_twin: DiscretePlant | None = None,
) -> PilResult:
    """Close the loop: firmware in QEMU, ``plant`` in Python, one FIFO round trip per sample.

    Parameters
    ----------
    artifact : Artifact
        Artifact whose image runs (built and cached by sha256).
    plant : DiscretePlant
        The plant; its outputs are sampled each period.
    steps : int
        Number of samples.
    reference : ndarray, optional
        (q,) constant absolute reference or (steps, q) sequence; by default the tracked outputs at the
        operating point (``Artifact.r_op``, zero without one).
    target : str, optional
        The core whose image runs: ``cortex-m0``, ``cortex-m3``, ``cortex-m4`` (default), ``cortex-m7``,
        ``cortex-m33`` or ``cortex-m55`` (see :mod:`gainlink.firmware.targets`).
    board : str, optional
        Its QEMU machine (default: the target's; a board alone implies its core).
    deadline_s : float
        How long to wait for one answer before declaring the firmware silent.
    twin : DiscretePlant, optional
        A second instance of the plant, in the same initial state: the float64 twin of the loop
        (:mod:`gainlink.proof.twin`) runs on it in step with the firmware, and the result compares the two.
    model_twin : DiscretePlant, optional
        The artifact's own model (:class:`ArtifactPlant`) started where the plant starts: the float64 law runs
        around it too, and the result holds its trace (the model twin of ``gainlink.hil.loop.model_twin``).
    quantised_twin : DiscretePlant, optional
        A fixed-point artifact only: a third instance of the plant, in the same initial state, on which the
        float64 law with the artifact's quantised coefficients closes the loop (the law the certified rounding
        bound compares with; :mod:`gainlink.hil.loop.pil_fixed`).

    Returns
    -------
    PilResult
        For a fixed-point artifact, ``fixed_point`` holds the oracle: the image bit for bit the model on the
        samples it received, and the deviation from the quantised twin beside the certified bound.
    """
    a = artifact
    _check_request(a, steps=steps, quantised_twin=quantised_twin)
    platform = resolve_cortex_m(target, board)
    board = platform.board.name
    R = np.broadcast_to(a.r_op if reference is None else np.asarray(reference, float), (steps, a.q))
    fixed = is_fixed(a)
    elf, magic = _image(a, target=platform.target.name, board=board)
    qt = None if quantised_twin is None else QuantisedTwin(a, plant=quantised_twin, steps=steps)
    rec = _PilRecord.empty(a, steps, x0=plant.state, fixed=fixed)
    with _qemu_fifos(elf, board=board, steps=steps) as (proc, fin, fout):
        _open_stream(
            proc, fin, fout, steps=steps, watchdog_periods=watchdog_periods, deadline_s=deadline_s, magic=magic
        )
        t_start = time.perf_counter()
        _exchange(a, plant, R, rec, link=(proc, fin, fout), deadline_s=deadline_s)
        elapsed = time.perf_counter() - t_start
        _await_exit(proc, deadline_s=deadline_s)
    tw, mt = _twin_after(a, twin, R, steps), _twin_after(a, model_twin, R, steps)  # off the per-sample path
    for k in range(steps if qt is not None else 0):
        qt.step(k, noise=np.zeros(a.p), r=R[k], d=np.zeros(a.m))
    twin_trace, comparison = (None, None) if tw is None else _compare_with_twin(a, tw, rec, R=R, steps=steps)
    check = None
    if fixed:
        model_plant = isinstance(plant, ArtifactPlant)  # the design model: the loop the certificate is about
        design_u = None if twin_trace is None else twin_trace.u
        check = fixed_pil_check(a, rec.raw, Y=rec.Y, R=R, quantised=qt, design_u=design_u, model_plant=model_plant)
    return _result(a, rec, R=R, elapsed=elapsed, twin=(twin_trace, comparison), model_twin=mt, check=check)


def _check_request(a: Artifact, *, steps: int, quantised_twin: DiscretePlant | None) -> None:
    """What :func:`run_pil` refuses before anything is built: a scheduled artifact (its PIL is
    :func:`~.pil_scheduled.run_scheduled_pil`), no steps, a quantised twin for a float32 artifact."""
    if a.schedule is not None:  # its image speaks the scheduled stream (main_sched.c)
        raise PlantError(f"artifact {a.name} is scheduled on {a.schedule.sigma}: its PIL is "
                         "gainlink.hil.loop.pil_scheduled.run_scheduled_pil (gainlink pil run runs it)")  # fmt: skip
    if steps < 1:
        raise PlantError("--steps must be at least 1")
    if quantised_twin is not None and not is_fixed(a):
        raise PlantError(f"artifact {a.name} is float32: no quantised twin (a fixed-point artifact has one)")


def _twin_after(a: Artifact, plant: DiscretePlant | None, R: np.ndarray, steps: int) -> TwinTrace | None:
    """The float64 law closing the loop on ``plant`` (in the run's initial state) for the run's samples, computed
    after the run (None without a plant)."""
    if plant is None:
        return None
    return run_twin(law_of(a).reference(a), outputs=plant.outputs, advance=lambda u: plant.advance(u=u),
                    noise=np.zeros((steps, a.p)), R=np.asarray(R, dtype=float), D=np.zeros((steps, a.m)),
                    S=np.zeros((steps, 0)), steps=steps)  # fmt: skip


def _result(a: Artifact, rec, *, R, elapsed: float, twin: tuple, model_twin, check) -> PilResult:
    """The PIL result from the run's record, its twins (the twin's trace and comparison; the model twin) and the
    fixed-point check."""
    twin_trace, comparison = twin
    steps = rec.Y.shape[0]
    fixed = check is not None
    return PilResult(
        y=rec.Y,
        u=rec.U,
        status=rec.S,
        saturated=rec.SAT,
        plant_state=np.array(rec.X),
        round_trip_us=rec.RT,
        steps_per_second=steps / elapsed if elapsed > 0 else float("inf"),
        twin=twin_trace,
        comparison=comparison,
        model_twin=model_twin,
        reference=np.array(R, dtype=float),
        fixed_point=check,
        fixed_run=fwfixed.FixedRun.from_records(rec.raw, a.q) if fixed else None,
    )


def _image(a: Artifact, *, target: str, board: str) -> tuple[Path, int]:
    """The image PIL runs (built and cached) and the first word of its answer: a fixed-point artifact's integer
    image (``main_fixed.c``), else the float image (``main.c``); both speak the stream of ``gl_stream.h``."""
    if is_fixed(a):
        elf, _ = fwfixed.image(a, target=target, board=board, options=fwfixed.REPLAY_OPTIONS)
        return elf, fwfixed.OUT_MAGIC
    return replay_image(a, target=target, board=board), fwqemu.OUT_MAGIC


def _compare_with_twin(
    a: Artifact, twin_trace: TwinTrace, rec: _PilRecord, *, R: np.ndarray, steps: int
) -> tuple[TwinTrace, TwinComparison]:
    """The twin's trace and its comparison with what the firmware did."""
    comparison = twin_comparison(
        t=np.arange(steps) * a.Ts,
        y=rec.Y,
        u=rec.U.astype(float),
        r=np.asarray(R, dtype=float),
        twin_y=twin_trace.y,
        twin_u=twin_trace.u,
        artifact=a,
    )
    return twin_trace, comparison


@dataclass
class _PilRecord:
    """What a PIL run records per sample."""

    Y: np.ndarray
    U: np.ndarray
    S: np.ndarray
    SAT: np.ndarray
    X: list
    RT: np.ndarray
    raw: np.ndarray  # the image's output records as they came

    @classmethod
    def empty(cls, a: Artifact, steps: int, *, x0: np.ndarray, fixed: bool = False) -> _PilRecord:
        dout = fwfixed.record_dtype(a) if fixed else fwqemu.record_dtypes(n=a.n, m=a.m, p=a.p, q=a.q)[1]
        return cls(
            Y=np.zeros((steps, a.p)),
            U=np.zeros((steps, a.m), dtype=np.float32),
            S=np.zeros(steps, dtype=np.int32),
            SAT=np.zeros((steps, a.m), dtype=bool),
            X=[x0],
            RT=np.zeros(steps),
            raw=np.zeros(steps, dtype=dout),
        )


@contextmanager
def _qemu_fifos(elf: Path, *, board: str, steps: int):
    """QEMU running ``elf`` with its semihosting files gl_in.bin/gl_out.bin as FIFOs: (process, in fd, out fd)."""
    with tempfile.TemporaryDirectory(prefix="gainlink-pil-") as tmp:
        work = Path(tmp)
        os.mkfifo(work / "gl_in.bin")
        os.mkfifo(work / "gl_out.bin")
        fin = os.open(work / "gl_in.bin", os.O_RDWR)
        fout = os.open(work / "gl_out.bin", os.O_RDWR)
        cmd = ["timeout", "-k", "2", str(60 + steps / 1000)] + fwqemu.qemu_command(
            elf, board=board, serial=f"file:{work / 'uart.log'}"
        )
        proc = subprocess.Popen(
            cmd, cwd=work, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        try:
            yield proc, fin, fout
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            os.close(fin)
            os.close(fout)


def _open_stream(
    proc: subprocess.Popen, fin: int, fout: int, *, steps: int, watchdog_periods: int, deadline_s: float, magic: int
) -> None:
    """Send the stream header (steps, one sample per record, watchdog) and check the firmware's answer (its
    header's first word ``magic``: the float or the fixed-point image's)."""
    os.write(fin, struct.pack("<4I", fwqemu.IN_MAGIC, steps, 1, watchdog_periods))
    header = _read_exact(fout, 32, proc=proc, deadline_s=deadline_s)
    got, count, *_ = struct.unpack("<8I", header)
    if got != magic or count != steps:
        raise FirmwareError("firmware answered with a bad stream header")


def _exchange(
    a: Artifact,
    plant: DiscretePlant,
    R: np.ndarray,
    rec: _PilRecord,
    *,
    link: tuple,
    deadline_s: float,
) -> None:
    """One FIFO round trip per sample: the plant's outputs in, the command out, the plant advanced."""
    proc, fin, fout = link
    din, _ = fwqemu.record_dtypes(n=a.n, m=a.m, p=a.p, q=a.q)
    dout = rec.raw.dtype
    fixed = "flags" in dout.names
    sample = np.zeros(1, dtype=din)
    for k in range(len(rec.Y)):
        y = plant.outputs()
        rec.Y[k] = y
        sample["y"] = y.astype(np.float32)
        if a.q:
            sample["r"][0, : a.q] = R[k].astype(np.float32)
        t0 = time.perf_counter()
        os.write(fin, sample.tobytes())
        out = np.frombuffer(_read_exact(fout, dout.itemsize, proc=proc, deadline_s=deadline_s), dtype=dout)[0]
        rec.RT[k] = (time.perf_counter() - t0) * 1e6
        rec.raw[k] = out
        rec.U[k] = out["u"]
        rec.S[k] = step_status(int(out["flags"]), int(out["sat"])) if fixed else out["status"]
        rec.SAT[k] = (int(out["sat"]) >> np.arange(a.m)) & 1
        plant.advance(u=rec.U[k].astype(float))
        rec.X.append(plant.state)


def _await_exit(proc: subprocess.Popen, *, deadline_s: float) -> None:
    """The firmware exits by itself after the last sample, with status 0."""
    try:
        proc.wait(timeout=deadline_s)
    except subprocess.TimeoutExpired:
        raise FirmwareError("firmware in QEMU did not exit after the last sample") from None
    if proc.returncode != 0:
        raise FirmwareError(f"firmware in QEMU failed: {fwqemu.EXIT_CODES.get(proc.returncode, proc.returncode)}")
