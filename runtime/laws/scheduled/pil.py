"""PIL of a scheduled law: its image's records checked bit for bit, the law's block of a PIL run
(:meth:`gainlink.laws.scheduled.law.ScheduledLaw.pil_check`).

The image is the artifact's (``firmware/ports/cortex-m/main.c``, one main for every law, replay only): in
``{tag, y, r, s}`` (``s`` the external scheduling signals, the schedule's ``external`` names in order), out the
scheduled law's record ``{status, flags, sat, u, sigma, state}`` (:mod:`gainlink.shipping.records`; its flags the one
flag table, the sigma flags among them). Two oracles, each fed the very float32 samples, references and signals the
image received, from reset: the scheduled float32 model
(:class:`~gainlink.laws.scheduled.model.ScheduledFloat32Loop`) and the host build of the same C
(:class:`~gainlink.laws.scheduled.native.NativeScheduledLoop`). Every record must equal theirs in its bits: status,
flags, saturation mask, command, sigma and the whole state.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ...shipping import records as law_records
from ...shipping.artifact import Artifact
from ..image import first_difference

LAW = "scheduled-float32"  # what the image runs (the host apps' ready line says the same)


@dataclass(frozen=True)
class ScheduledPilCheck:
    """What a scheduled PIL run showed: the law, each oracle's verdict (``first_difference_*``: the first step whose
    record differs and its field) and sigma's ``schedule`` block (range covered, fastest rate, held / clipped /
    rate-limited steps)."""

    law: str
    steps: int
    bit_exact_model: bool
    first_difference_model: dict | None
    bit_exact_host: bool
    first_difference_host: dict | None
    schedule: dict

    def to_dict(self) -> dict:
        """JSON form (the ``scheduled`` block of the PIL summary)."""
        return asdict(self)


def image_records(a: Artifact, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray, host: bool,
                  status_flags: Any) -> np.ndarray:  # fmt: skip
    """The records the image writes for these float32 samples from reset, computed by the float32 model (its sigma
    flags read by ``status_flags``) or, with ``host``, by the host build of the C (the same record,
    :func:`gainlink.shipping.records.layout`)."""
    from .model import ScheduledFloat32Loop
    from .native import NativeScheduledLoop

    Sx = S if S.shape[1] else None
    if host:
        return NativeScheduledLoop(a).host.run(Y, R, Sx)
    out = np.zeros(Y.shape[0], dtype=law_records.layout(a).dtype)
    tr = ScheduledFloat32Loop(a).run(Y.astype(np.float64), R.astype(np.float64), Sx)
    out["u"], out["state"], out["sigma"] = tr.u, tr.state, tr.sigma
    out["sat"] = (tr.saturated.astype(np.uint32) << np.arange(a.m, dtype=np.uint32)).sum(axis=1)
    out["status"] = np.where(tr.fault, -2, np.where(tr.saturated.any(axis=1), 1, 0))
    out["flags"] = [status_flags(int(f), fault=bool(x)) for f, x in zip(tr.sigma_flags, tr.fault, strict=True)]
    return out


def image_stream(artifact: Artifact, *, target: str, board: str) -> Any:
    """The scheduled law's replay-only image (``main.c`` on the scheduled law) and its stream
    (:func:`.image.law_image_stream`): its records' flags are the status flags (the sigma flags among them), its
    ``sigma`` the sigma the step used."""
    from ..base import Step
    from ..image import law_image_stream

    def decode(rec: Any) -> Step:
        return Step(u=rec["u"].astype(float), flags=int(rec["flags"]), sat=int(rec["sat"]),
                    sigma=float(rec["sigma"]))  # fmt: skip

    return law_image_stream(artifact, target=target, board=board, decode=decode)


def pil_check(a: Artifact, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray, trace: Any,
              status_flags: Any) -> dict:  # fmt: skip
    """The ``scheduled`` block of a PIL run (module docstring); ``trace`` holds sigma and the status flags per step
    (for the schedule block), ``status_flags`` reads the float32 model's sigma flags."""
    from .run import schedule_metrics

    Y32, R32, S32 = (np.asarray(X, dtype=np.float32) for X in (Y, R, S))
    model = first_difference(records, image_records(a, Y=Y32, R=R32, S=S32, host=False, status_flags=status_flags))
    host = first_difference(records, image_records(a, Y=Y32, R=R32, S=S32, host=True, status_flags=status_flags))
    check = ScheduledPilCheck(law=LAW, steps=len(records), bit_exact_model=model is None, first_difference_model=model,
                              bit_exact_host=host is None, first_difference_host=host,
                              schedule=schedule_metrics(a, trace))  # fmt: skip
    return {"scheduled": check}


def pil_lines(block: Any) -> list[str]:
    """The PIL summary's lines on the scheduled image: against the float32 model and the host C, and sigma."""
    from .run import schedule_lines

    if not block:
        return []
    sch = block.to_dict() if hasattr(block, "to_dict") else block
    model = "bit for bit" if sch["bit_exact_model"] else f"DIFFERS at {sch['first_difference_model']}"
    host = "bit for bit" if sch["bit_exact_host"] else f"DIFFERS at {sch['first_difference_host']}"
    return [f"  scheduled law: the float32 model {model}, the host C {host}", *schedule_lines(sch["schedule"])]


def cost(artifact: Artifact, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
    """Instructions per call of ``gl_sched_step`` (callees included) replaying the samples on the image
    (:func:`gainlink.firmware.cost.count_step_instructions`, the one count for every law)."""
    from ...firmware.build import replay_image
    from ...firmware.cost import count_step_instructions

    elf = replay_image(artifact, target=target, board=board)
    return count_step_instructions(elf, artifact, Y=Y, R=R if artifact.q else None, S=S if S.shape[1] else None,
                                   board=board)  # fmt: skip
