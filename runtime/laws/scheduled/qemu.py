"""The scheduled law on a Cortex-M image under ``qemu-system-arm`` (``firmware/ports/cortex-m/main.c``)."""

from __future__ import annotations

import numpy as np

from ...firmware import qemu as fwqemu
from ...firmware.build import replay_image
from ...firmware.targets import resolve_cortex_m
from ...shipping.artifact import Artifact
from .native import raw_of_records, scheduled_trace_from_raw
from .reference import ScheduledTrace


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
    rec = fwqemu.replay(elf, a, board=platform.board.name, Y=Y, R=R, S=S if a.schedule.external else None)
    return scheduled_trace_from_raw(raw_of_records(rec), a=a)
