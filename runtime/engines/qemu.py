"""The ``qemu`` engine: the Cortex-M4F image under ``qemu-system-arm``, samples via semihosting files."""

from __future__ import annotations

import numpy as np

from ..firmware import qemu as fwqemu
from ..firmware.build import DEFAULT_BOARD, build
from ..proof.reference import Trace
from ..shipping.artifact import Artifact
from .native import trace_from_raw


def run_raw(
    artifact: Artifact, Y: np.ndarray, R: np.ndarray | None, *, board: str = DEFAULT_BOARD
) -> dict[str, np.ndarray]:
    """Replay a block through the image on ``board``; return float32 outputs (``u sat xh z fault status``)."""
    a = artifact
    res = build(a, target="cortex-m4", board=board)
    rec = fwqemu.replay(res.files["elf"], board=board, n=a.n, m=a.m, p=a.p, q=a.q, Y=Y, R=R)
    return {
        "u": np.array(rec["u"]),
        "sat": np.array(rec["sat"]),
        "xh": np.array(rec["xh"]),
        "z": np.array(rec["z"][:, : a.q]),
        "fault": (rec["status"] == -2).astype(np.uint8),
        "status": np.array(rec["status"]),
    }


def run(artifact: Artifact, Y: np.ndarray, R: np.ndarray, *, board: str = DEFAULT_BOARD) -> Trace:
    """Replay ``Y`` (N, p) and ``R`` (N, q) through the Cortex-M4F image in QEMU.

    Parameters
    ----------
    artifact : Artifact
        The artifact (its image is built and cached on first use).
    Y, R : ndarray
        Measurements and references, one row per step (cast to float32).
    board : str
        ``mps2-an386`` (default) or ``netduinoplus2``.

    Returns
    -------
    Trace
        The firmware's outputs (float32 values as float64 arrays).
    """
    artifact.require_unscheduled("the qemu engine")
    return trace_from_raw(run_raw(artifact, Y, R, board=board), m=artifact.m)
