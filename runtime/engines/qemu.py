"""The ``qemu`` engine: a Cortex-M image under ``qemu-system-arm``, samples via semihosting files."""

from __future__ import annotations

import numpy as np

from ..firmware import qemu as fwqemu
from ..firmware.build import replay_image
from ..firmware.targets import resolve_cortex_m
from ..shipping.artifact import Artifact
from ..shipping.records import column


def run_raw(
    artifact: Artifact, Y: np.ndarray, R: np.ndarray | None, *, target: str | None = None, board: str | None = None
) -> dict[str, np.ndarray]:
    """Replay a block through the image of ``target`` on ``board``; return float32 outputs
    (``u sat xh z fault status``). Default: cortex-m4 on mps2-an386; a board alone implies its core."""
    a = artifact
    platform = resolve_cortex_m(target, board)
    elf = replay_image(a, target=platform.target.name, board=platform.board.name)
    rec = fwqemu.replay(elf, a, board=platform.board.name, Y=Y, R=R if a.q else None)
    return {
        "u": column(rec, "u"),
        "sat": column(rec, "sat"),
        "xh": column(rec, "xh"),
        "z": np.ascontiguousarray(column(rec, "z")[:, : a.q]),
        "fault": (rec["status"] == -2).astype(np.uint8),
        "status": column(rec, "status"),
    }
