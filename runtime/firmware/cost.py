"""Instructions per control step, counted by this project's QEMU TCG plugin (``firmware/tools/gl_insn_count.c``).

DWT's cycle counter is not emulated, so the cost is measured as guest instructions executed inside
``gl_loop_step`` (its symbol range in the ELF; the step inlines everything it calls). The count is
exact and deterministic.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..artifact import Artifact
from ..errors import FirmwareError, ToolchainError
from ..fileio import exclusive_lock
from . import qemu as fwqemu
from .build import cache_root, firmware_dir
from .size import symbol_sizes

STEP_SYMBOL = "gl_loop_step"


def build_plugin() -> Path:
    """Compile the instruction-count plugin (cached; rebuilt when its source changes)."""
    src = firmware_dir() / "tools" / "gl_insn_count.c"
    out = cache_root() / "plugin" / "libgl_insn_count.so"
    if _fresh(out, src):
        return out
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise ToolchainError("no host C compiler (cc) to build the QEMU plugin")
    with exclusive_lock(out.with_name(".lock")):  # another process may have built it while this one waited
        if _fresh(out, src):
            return out
        tmp = out.with_suffix(".tmp.so")
        proc = subprocess.run(
            [cc, "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(tmp), str(src)],
            capture_output=True,
            text=True,
        )
        if proc.returncode != 0:
            raise ToolchainError(f"building the QEMU plugin failed: {proc.stderr.strip()[-500:]}")
        tmp.replace(out)
    return out


def _fresh(out: Path, src: Path) -> bool:
    return out.is_file() and out.stat().st_mtime >= src.stat().st_mtime


@dataclass(frozen=True)
class StepCost:
    """Instructions executed inside the step over a replay."""

    instructions: int
    calls: int

    @property
    def per_step(self) -> float:
        """Mean instructions per call."""
        return self.instructions / self.calls if self.calls else float("nan")


def count_step_instructions(
    elf: Path, artifact: Artifact, *, Y: np.ndarray, R: np.ndarray, board: str = "mps2-an386"
) -> StepCost:
    """Replay ``Y``, ``R`` through ``elf`` in QEMU with the plugin counting inside ``gl_loop_step``."""
    sym = symbol_sizes(elf, (STEP_SYMBOL,)).get(STEP_SYMBOL)
    if sym is None:
        raise FirmwareError(f"{elf} has no {STEP_SYMBOL} symbol")
    lo, hi = sym["address"], sym["address"] + sym["size"]
    plugin = build_plugin()
    with tempfile.TemporaryDirectory(prefix="gainlink-cost-") as tmp:
        result = Path(tmp) / "count.txt"
        args = ["-plugin", f"{plugin},lo={lo:#x},hi={hi:#x},entry={lo:#x},out={result}"]
        a = artifact
        fwqemu.replay(elf, board=board, n=a.n, m=a.m, p=a.p, q=a.q, Y=Y, R=R, plugin=args)
        fields = dict(item.split("=") for item in result.read_text().split())
    return StepCost(instructions=int(fields["insns"]), calls=int(fields["calls"]))


def law_macs(artifact: Artifact) -> int:
    """Multiply-accumulates of one step of the law as DESIGN.md writes it (matrix-vector products)."""
    a = artifact
    n, m, p, q = a.n, a.m, a.p, a.q
    macs = m * n + m * q + q * p + q  # K xh (or K xc), Ki z, Ci y, Ts e
    if a.anti_windup == "backcalc":
        macs += q * m
    if a.observer_form == "current":
        macs += 2 * p * n + n * n + n * m  # M (y - Cd xh), Ad xc, Bd u
    else:
        macs += n * n + n * m + 2 * p * n + p * m  # Ad xh, Bd u, Cd xh, L (...), Dd u
    return macs


def implemented_macs(artifact: Artifact) -> int:
    """Multiply-accumulates the firmware's step performs (coefficient stream minus the 2 m limits and the
    m + p operating-point offsets, which are subtractions)."""
    a = artifact
    n, m, p, q = a.n, a.m, a.p, a.q
    vrow = n + (p if a.observer_form == "current" else 0) + q
    zrow = p + 1 + (m if a.anti_windup == "backcalc" else 0)
    return m * vrow + q * zrow + n * (n + m + p)
