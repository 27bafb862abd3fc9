"""The scheduled law on a Cortex-M image under ``qemu-system-arm`` (``firmware/ports/cortex-m/main_sched.c``)."""

from __future__ import annotations

import numpy as np

from ..firmware import qemu_sched
from ..firmware.build import replay_image
from ..firmware.targets import resolve_cortex_m
from ..proof.scheduled_reference import ScheduledTrace
from ..shipping.artifact import Artifact
from .sched_native import scheduled_trace_from_raw


def dims(a: Artifact) -> dict:
    """``n m p q e`` of a scheduled artifact (the image's stream shape)."""
    return {"n": a.n, "m": a.m, "p": a.p, "q": a.q, "e": len(a.schedule.external)}


def run(
    artifact: Artifact,
    Y: np.ndarray,
    R: np.ndarray | None,
    S: np.ndarray | None = None,
    *,
    target: str | None = None,
    board: str | None = None,
) -> ScheduledTrace:
    """Replay ``Y`` (N, p), ``R`` (N, q) and the external signals ``S`` (N, e) through the scheduled image of
    ``target`` on ``board`` (default cortex-m4 on mps2-an386) from its reset state.

    Returns
    -------
    ScheduledTrace
        The firmware's outputs (float32 values as float64 arrays).
    """
    a = artifact
    platform = resolve_cortex_m(target, board)
    elf = replay_image(a, target=platform.target.name, board=platform.board.name)  # without the bus nodes
    N = np.asarray(Y).reshape(-1, a.p).shape[0]
    R = np.zeros((N, a.q)) if R is None else R
    rec = qemu_sched.replay(elf, board=platform.board.name, dims=dims(a),
                            npts=a.schedule.points.size, Y=Y, R=R, S=S)  # fmt: skip
    raw = {k: np.array(rec[k]) for k in ("u", "sat", "sflags", "state", "status")}
    return scheduled_trace_from_raw(raw, a=a)
