"""The ``qemu`` engine: a Cortex-M image under ``qemu-system-arm``, samples via semihosting files."""

from __future__ import annotations

import numpy as np

from ..firmware import qemu as fwqemu
from ..firmware.build import replay_image
from ..firmware.targets import resolve_cortex_m
from ..proof.reference import Trace
from ..shipping.artifact import Artifact
from ..shipping.codegen_fixed import is_fixed
from ..shipping.records import column
from . import fixed as fixed_engine
from .native import trace_from_raw


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


def run(
    artifact: Artifact, Y: np.ndarray, R: np.ndarray, *, target: str | None = None, board: str | None = None
) -> Trace:
    """Replay ``Y`` (N, p) and ``R`` (N, q) through a Cortex-M image in QEMU.

    Parameters
    ----------
    artifact : Artifact
        The artifact (its image is built and cached on first use).
    Y, R : ndarray
        Measurements and references, one row per step (cast to float32).
    target : str, optional
        ``cortex-m0``, ``cortex-m3``, ``cortex-m4`` (default), ``cortex-m7``, ``cortex-m33`` or ``cortex-m55``.
    board : str, optional
        Its QEMU board (default: the target's, see :mod:`gainlink.firmware.targets`).

    Returns
    -------
    Trace
        The firmware's outputs (float32 values as float64 arrays).
    """
    artifact.require_unscheduled("the qemu engine")
    if is_fixed(artifact):  # its implementation is the integer law: the fixed-point image
        return fixed_engine.run_qemu(artifact, Y, R, target=target, board=board)
    return trace_from_raw(run_raw(artifact, Y, R, target=target, board=board), m=artifact.m)
