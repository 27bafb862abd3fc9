"""Instructions per scheduled step (``gl_sched_step``) on a Cortex-M image, counted by the QEMU TCG plugin as
:mod:`gainlink.firmware.cost` counts ``gl_loop_step``: from each call's entry to its return, callees included;
the image masks interrupts around each step."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from ..shipping.artifact import Artifact
from . import qemu_sched
from .build import DEFAULT_BOARD
from .cost import StepCost, build_plugin, return_addresses
from .size import symbol_sizes

SCHED_STEP_SYMBOL = "gl_sched_step"


def count_sched_step_instructions(
    elf: Path, artifact: Artifact, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, board: str = DEFAULT_BOARD
) -> StepCost:
    """Replay ``Y``, ``R``, ``S`` through the scheduled image ``elf`` on ``board``, counting every call of
    ``gl_sched_step``."""
    sym = symbol_sizes(elf, (SCHED_STEP_SYMBOL,)).get(SCHED_STEP_SYMBOL)
    returns = return_addresses(elf, SCHED_STEP_SYMBOL)
    if sym is None or not returns:
        raise FirmwareError(f"{elf} has no directly called {SCHED_STEP_SYMBOL}")
    lo, hi = sym["address"], sym["address"] + sym["size"]
    a = artifact
    dims = {"n": a.n, "m": a.m, "p": a.p, "q": a.q, "e": len(a.schedule.external)}
    with tempfile.TemporaryDirectory(prefix="gainlink-cost-") as tmp:
        result = Path(tmp) / "count.txt"
        spec = [f"{build_plugin()}", f"lo={lo:#x}", f"hi={hi:#x}", f"entry={lo:#x}", f"out={result}"]
        spec += [f"ret={r:#x}" for r in returns]
        qemu_sched.replay(elf, board=board, dims=dims, npts=a.schedule.points.size, Y=Y, R=R, S=S,
                          plugin=["-plugin", ",".join(spec)])  # fmt: skip
        fields = {k: int(v) for k, v in (item.split("=") for item in result.read_text().split())}
    return StepCost(instructions=fields["insns"], calls=fields["calls"], own=fields["own"], cheapest=fields["min"],
                    dearest=fields["max"])  # fmt: skip
