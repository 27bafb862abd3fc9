"""PIL of a scheduled artifact (schema 2): its Cortex-M image runs ``gl_sched_step`` in closed loop with a plant
in Python, and is checked bit for bit.

The image is the scheduled one (``firmware/ports/cortex-m/main_sched.c``, replay only), driven through the FIFOs of
:mod:`.pil` one record per step (block 1): in ``{y, r, s}`` (``s`` the external scheduling signals, the schedule's
``external`` names in order), out ``{status, sat, sflags, u, state}`` (:mod:`gainlink.firmware.qemu_sched`). Sigma
is the measured output the schedule names, or the external signal given per step; a plant with a ``schedule(s)``
method (``scheduled_model``) hears the external signals before each sample, as in SIL.

Two oracles, each fed the very float32 samples, references and signals the image received, from reset: the
scheduled float32 model (:class:`~gainlink.proof.scheduled_float32.ScheduledFloat32Loop`) and the host build of the
same C (:class:`~gainlink.engines.sched_native.NativeScheduledLoop`). Every record must equal theirs in its bits:
status, saturation mask, sigma flags, command and the whole state (sigma among it). Beside the run, the float64
scheduled law closes the loop on a second plant (the closed-loop twin) and around the design's own model at the
sigma it runs at (the model twin, ``Law.design_model``); both are computed after the run.
"""

from __future__ import annotations

import os
import struct
import time
from dataclasses import asdict, dataclass

import numpy as np
from gainlink.engines.sched_native import NativeScheduledLoop
from gainlink.errors import FirmwareError, PlantError
from gainlink.firmware import qemu_sched
from gainlink.firmware.build import replay_image
from gainlink.firmware.targets import resolve_cortex_m
from gainlink.laws import law_of
from gainlink.laws.scheduled import status_flags
from gainlink.laws.scheduled_run import schedule_metrics
from gainlink.proof.scheduled_float32 import ScheduledFloat32Loop
from gainlink.proof.twin import run_twin
from gainlink.shipping.artifact import Artifact

from ..plants import tank  # noqa: F401 - registers the tank of the scheduled examples
from ..plants.fmi import signal_name
from .pil import DiscretePlant, PilResult, _await_exit, _compare_with_twin, _qemu_fifos, _read_exact
from .pil_fixed import first_difference

LAW = "scheduled-float32"  # what the image runs (the host apps' ready line says the same)


@dataclass(frozen=True)
class ScheduledPilCheck:
    """What a scheduled PIL run showed: the law, each oracle's verdict (``first_difference_*``: the first step whose
    record differs and its field), sigma's ``schedule`` block (:func:`~.sched_metrics.schedule_metrics`: range
    covered, fastest rate, held / clipped / rate-limited steps) and where the model twin started."""

    law: str
    steps: int
    bit_exact_model: bool
    first_difference_model: dict | None
    bit_exact_host: bool
    first_difference_host: dict | None
    schedule: dict
    model_twin_start: str

    def to_dict(self) -> dict:
        """JSON form (the ``scheduled`` block of the PIL summary)."""
        return asdict(self)


@dataclass(frozen=True)
class _SigmaTrace:
    """Sigma per step and its status flags, as the law's ``schedule_metrics`` reads a trace."""

    sigma: np.ndarray
    flags: np.ndarray


def external_ramps(a: Artifact, spec: dict[str, tuple[float, float]], steps: int) -> np.ndarray:
    """The external scheduling signals per step (steps, e): each ``NAME: (start, end)`` a linear ramp over the run;
    one line when a name is not an external signal of ``a`` or one is missing."""
    names = a.schedule.external
    unknown = sorted(set(spec) - set(names))
    if unknown:
        raise PlantError(f"--schedule-signal {unknown[0]}: not an external scheduling signal of {a.name} "
                         f"(external: {', '.join(names) or 'none'})")  # fmt: skip
    missing = [n for n in names if n not in spec]
    if missing:
        raise PlantError(f"artifact {a.name} is scheduled on {', '.join(missing)}: give --schedule-signal "
                         f"{missing[0]}=START[,END]")  # fmt: skip
    return np.column_stack([np.linspace(*spec[n], steps) for n in names] or [np.zeros((steps, 0))])


def image_records(a: Artifact, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray, host: bool) -> np.ndarray:
    """The records the image writes for these float32 samples from reset, computed by the float32 model (or, with
    ``host``, by the host build of the C)."""
    _, dout = qemu_sched.record_dtypes(n=a.n, m=a.m, p=a.p, q=a.q, e=len(a.schedule.external))
    out = np.zeros(Y.shape[0], dtype=dout)
    Sx = S if S.shape[1] else None
    if host:
        raw = NativeScheduledLoop(a).run_raw(Y, R, Sx)
        for name in ("status", "sat", "sflags", "u", "state"):
            out[name] = raw[name]
        return out
    tr = ScheduledFloat32Loop(a).run(Y.astype(np.float64), R.astype(np.float64), Sx)
    out["u"], out["state"], out["sflags"] = tr.u, tr.state, tr.sigma_flags
    out["sat"] = (tr.saturated.astype(np.uint32) << np.arange(a.m, dtype=np.uint32)).sum(axis=1)
    out["status"] = np.where(tr.fault, -2, np.where(tr.saturated.any(axis=1), 1, 0))
    return out


def scheduled_model_twin(a: Artifact, plant: DiscretePlant, *, S: np.ndarray):
    """The model (the design's model at its law's sigma) started where ``plant`` starts (taken now, before the run),
    and a note on where; ``(None, why)`` when the plant is not a ``gainlink.hil`` plant or the points give no x_op."""
    inner = getattr(plant, "plant", None)
    if inner is None:
        return None, "off: the plant is not a gainlink.hil plant (its state does not map onto the model's)"
    law = law_of(a)
    sigma0 = law.sigma_of(a, plant.outputs(), S[0] if len(S) else np.zeros(S.shape[1]))
    state = dict(zip((signal_name(s) for s in inner.state_names), np.asarray(inner.state(), float)))
    return law.design_model(a, state=state, deviation=False, sigma=sigma0)


def run_scheduled_pil(
    artifact: Artifact,
    *,
    plant: DiscretePlant,
    steps: int,
    reference: np.ndarray | None = None,
    signals: np.ndarray | None = None,
    target: str | None = None,
    board: str | None = None,
    deadline_s: float = 10.0,
    twin: DiscretePlant | None = None,
    model_twin: bool = True,
) -> PilResult:
    """Close the loop with the scheduled image in QEMU (module docstring).

    Parameters
    ----------
    artifact : Artifact
        A scheduled artifact.
    plant, steps, target, board, deadline_s, twin
        As :func:`~.pil.run_pil`'s (``twin``: the float64 scheduled law runs on it).
    reference : ndarray, optional
        (q,) constant absolute reference or (steps, q); by default the tracked outputs at the trim of the start
        sigma.
    signals : ndarray, optional
        (steps, e) external scheduling signals; required when the schedule has external signals.
    model_twin : bool
        Run the scheduled model twin (when the plant is a ``gainlink.hil`` plant).

    Returns
    -------
    PilResult
        With ``scheduled`` (:class:`ScheduledPilCheck`), ``sigma`` and ``sigma_flags`` per step.
    """
    a = artifact
    if a.schedule is None:
        raise PlantError(f"artifact {a.name} is not scheduled: use gainlink.hil.loop.pil.run_pil")
    if steps < 1:
        raise PlantError("--steps must be at least 1")
    e = len(a.schedule.external)
    S = np.zeros((steps, e)) if signals is None else np.asarray(signals, dtype=float).reshape(steps, -1)
    if S.shape[1] != e:
        raise PlantError(f"artifact {a.name} needs {e} external scheduling signal(s) per step, got {S.shape[1]}")
    platform = resolve_cortex_m(target, board)
    elf = replay_image(a, target=platform.target.name, board=platform.board.name)
    follow = _follower(plant)
    if follow is not None and steps:
        follow(S[0])
    R = np.broadcast_to(_start_reference(a, plant, S) if reference is None else np.asarray(reference, float),
                        (steps, a.q))  # fmt: skip
    model, note = scheduled_model_twin(a, plant, S=S) if model_twin else (None, "off")
    rec = _Record.empty(a, steps, x0=plant.state)
    with _qemu_fifos(elf, board=platform.board.name, steps=steps) as link:
        _open(link, steps=steps, deadline_s=deadline_s)
        t0 = time.perf_counter()
        _exchange(a, plant, R, S, rec, link=link, deadline_s=deadline_s)
        elapsed = time.perf_counter() - t0
        _await_exit(link[0], deadline_s=deadline_s)
    tw = None if twin is None else _twin(a, twin, R, S, follow=_follower(twin))  # off the per-sample path
    mt = None if model is None else _twin(a, model, R, S, follow=None, on_sigma=model.follow, bare=True)
    return _result(a, rec, R=R, S=S, elapsed=elapsed, twin=tw, model_twin=mt, note=note)


def _follower(plant: DiscretePlant):
    """The plant's ``schedule(s)`` (a plant whose dynamics follow the external signals), else None."""
    return getattr(getattr(plant, "plant", plant), "schedule", None)


def _start_reference(a: Artifact, plant: DiscretePlant, S: np.ndarray) -> np.ndarray:
    """The tracked outputs at the trim of the start sigma (as a scheduled SIL run's default)."""
    sch = a.schedule
    raw = plant.outputs()[sch.index] if sch.source == "output" else S[0, sch.index]
    return a.Ci @ sch.trim_at(sch.clip(float(raw)))[1]


def _twin(a: Artifact, plant, R, S, *, follow, on_sigma=None, bare: bool = False):
    """The float64 scheduled law closing the loop on ``plant`` (in the run's initial state) for the run's samples
    (``bare``: a model advanced as ``advance(u)``)."""
    steps = S.shape[0]
    advance = plant.advance if bare else (lambda u: plant.advance(u=u))
    return run_twin(law_of(a).reference(a), outputs=plant.outputs, advance=advance, noise=np.zeros((steps, a.p)),
                    R=np.asarray(R, dtype=float), D=np.zeros((steps, a.m)), S=S, steps=steps, on_signals=follow,
                    on_sigma=on_sigma)  # fmt: skip


@dataclass
class _Record:
    """What a scheduled PIL run records per sample (the image's records as they came in ``raw``)."""

    Y: np.ndarray
    X: list
    RT: np.ndarray
    sent: np.ndarray
    raw: np.ndarray

    @classmethod
    def empty(cls, a: Artifact, steps: int, *, x0: np.ndarray) -> _Record:
        din, dout = qemu_sched.record_dtypes(n=a.n, m=a.m, p=a.p, q=a.q, e=len(a.schedule.external))
        return cls(Y=np.zeros((steps, a.p)), X=[x0], RT=np.zeros(steps), sent=np.zeros(steps, dtype=din),
                   raw=np.zeros(steps, dtype=dout))  # fmt: skip


def _open(link: tuple, *, steps: int, deadline_s: float) -> None:
    """The scheduled stream's header (one record per block) and the image's answer."""
    proc, fin, fout = link
    os.write(fin, struct.pack("<4I", qemu_sched.IN_MAGIC, steps, 1, 0))
    magic, count, *_ = struct.unpack("<8I", _read_exact(fout, 32, proc=proc, deadline_s=deadline_s))
    if magic != qemu_sched.OUT_MAGIC or count != steps:
        raise FirmwareError("scheduled firmware answered with a bad stream header (image built for another artifact?)")


def _exchange(a: Artifact, plant, R, S, rec: _Record, *, link: tuple, deadline_s: float) -> None:
    """One FIFO round trip per sample: outputs, reference and signals in, the record out, the plant advanced."""
    proc, fin, fout = link
    dout, follow, e = rec.raw.dtype, _follower(plant), S.shape[1]
    for k in range(len(rec.Y)):
        if follow is not None and k:
            follow(S[k])
        y = plant.outputs()
        rec.Y[k] = y
        sample = rec.sent[k : k + 1]
        sample["y"] = y.astype(np.float32)
        sample["r"] = R[k].astype(np.float32)
        if e:
            sample["s"] = S[k].astype(np.float32)
        t0 = time.perf_counter()
        os.write(fin, sample.tobytes())
        out = np.frombuffer(_read_exact(fout, dout.itemsize, proc=proc, deadline_s=deadline_s), dtype=dout)[0]
        rec.RT[k] = (time.perf_counter() - t0) * 1e6
        rec.raw[k] = out
        plant.advance(u=out["u"].astype(float))
        rec.X.append(plant.state)


def _result(a: Artifact, rec: _Record, *, R, S, elapsed: float, twin, model_twin, note: str) -> PilResult:
    """The PIL result: the run, its twins and the check against both oracles."""
    steps, raw = len(rec.Y), rec.raw
    e = S.shape[1]
    Y32, R32 = rec.sent["y"].reshape(steps, a.p), rec.sent["r"].reshape(steps, a.q)
    S32 = rec.sent["s"].reshape(steps, -1)[:, :e]
    sigma = raw["state"][:, a.n + a.m + a.p + a.q].astype(np.float64)
    flags = raw["sflags"].astype(np.int64)
    model = first_difference(raw, image_records(a, Y=Y32, R=R32, S=S32, host=False))
    host = first_difference(raw, image_records(a, Y=Y32, R=R32, S=S32, host=True))
    check = ScheduledPilCheck(
        law=LAW, steps=steps, bit_exact_model=model is None, first_difference_model=model,
        bit_exact_host=host is None, first_difference_host=host,
        schedule=schedule_metrics(a, _SigmaTrace(sigma, _status(raw))), model_twin_start=note,
    )  # fmt: skip
    U = raw["u"].reshape(steps, a.m).copy()
    twin_trace, comparison = (None, None) if twin is None else _compare_with_twin(a, twin, _Cmds(rec.Y, U), R=R,
                                                                                   steps=steps)  # fmt: skip
    return PilResult(
        y=rec.Y,
        u=U,
        status=raw["status"].astype(np.int32),
        saturated=((raw["sat"][:, None] >> np.arange(a.m, dtype=np.uint32)) & 1).astype(bool),
        plant_state=np.array(rec.X),
        round_trip_us=rec.RT,
        steps_per_second=steps / elapsed if elapsed > 0 else float("inf"),
        twin=twin_trace,
        comparison=comparison,
        model_twin=model_twin,
        reference=np.array(R, dtype=float),
        scheduled=check,
        sigma=sigma,
        sigma_flags=flags,
    )


def _status(raw: np.ndarray) -> np.ndarray:
    """The status flags of the image's records (its sigma flags and fault)."""
    return np.array([status_flags(int(f), fault=int(st) == -2) for f, st in zip(raw["sflags"], raw["status"])],
                    dtype=np.int64)  # fmt: skip


@dataclass(frozen=True)
class _Cmds:
    """The samples and commands of a run, as :func:`~.pil._compare_with_twin` reads a record."""

    Y: np.ndarray
    U: np.ndarray
