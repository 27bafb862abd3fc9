"""Instructions per control step, counted by this project's QEMU TCG plugin (``firmware/tools/gl_insn_count.c``).

DWT's cycle counter is not emulated, so the cost is measured as guest instructions executed from the
entry of the law's own step function (``gl_loop_step``, ``gl_fixed_step`` or ``gl_sched_step``:
:func:`gainlink.shipping.law_c.step_symbol`; gl_law.h's inline wrapper around it, which copies words and sets
flag bits, is not counted) to its return, callees included: on the soft-float cores (M0, M3) most of the
work is in libgcc's float routines and gl_fmaf, outside the step's own symbol, and counting inside the
symbol only would flatter them. The instructions inside the symbol are reported beside it (``own``).
The image masks interrupts around each step it replays, so no handler is counted. The count is exact
and deterministic.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FirmwareError, ToolchainError
from ..fileio import exclusive_lock
from ..shipping.artifact import Artifact
from ..shipping.law_c import step_symbol
from . import qemu as fwqemu
from .build import DEFAULT_BOARD, cache_root, firmware_dir
from .size import symbol_sizes, tool

_FUNC = re.compile(r"^[0-9a-f]+ <(\S+)>:$")
_CALL = re.compile(r"^\s*([0-9a-f]+):\s+(?:[0-9a-f]{4}\s+){2}bl\s+[0-9a-f]+ <(\S+)>$")


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
    """Instructions executed by the calls of the step over a replay.

    ``instructions``: from each call's entry to its return, callees included, summed over ``calls``;
    ``own``: those inside the step's own symbol; ``cheapest`` and ``dearest``: the fewest and most
    instructions one call took.
    """

    instructions: int
    calls: int
    own: int = 0
    cheapest: int = 0
    dearest: int = 0
    each: tuple[int, ...] = ()  # every call's count in call order, when asked for (count_calls(each=True))

    @property
    def per_step(self) -> float:
        """Mean instructions per call, callees included."""
        return self.instructions / self.calls if self.calls else float("nan")

    @property
    def own_per_step(self) -> float:
        """Mean instructions per call inside the step's own symbol."""
        return self.own / self.calls if self.calls else float("nan")


def return_addresses(elf: Path, symbol: str, callers: tuple[str, ...] = ()) -> list[int]:
    """Addresses right after every direct call (``bl``) of ``symbol`` in ``elf``: where its calls return (only the
    calls made in the functions ``callers``, when given)."""
    out = subprocess.run(
        [tool("arm-none-eabi-objdump"), "-d", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    sites, function = [], ""
    for line in out.splitlines():
        if f := _FUNC.match(line):
            function = f.group(1)
        elif (m := _CALL.match(line)) and m.group(2) == symbol and (not callers or function in callers):
            sites.append(int(m.group(1), 16))
    return [site + 4 for site in sites]  # a Thumb-2 bl is 4 bytes


def count_step_instructions(
    elf: Path,
    artifact: Artifact,
    *,
    Y: np.ndarray,
    R: np.ndarray | None,
    S: np.ndarray | None = None,
    board: str = DEFAULT_BOARD,
    law: str | None = None,
    each: bool = False,
) -> StepCost:
    """Replay ``Y``, ``R`` (and a scheduled law's external signals ``S``) through ``elf`` on ``board`` in QEMU,
    counting every call of the law's step function (``law``: the law the image runs when it is not the artifact's
    own, a ``GL_LAW`` baseline; ``each``: every step's count too)."""
    symbol = step_symbol(artifact, law=law)
    return count_calls(elf, artifact, symbol=symbol, Y=Y, R=R, S=S, board=board, law=law, each=each)


def count_calls(
    elf: Path,
    artifact: Artifact,
    *,
    symbol: str,
    Y: np.ndarray,
    R: np.ndarray | None,
    S: np.ndarray | None = None,
    board: str = DEFAULT_BOARD,
    law: str | None = None,
    each: bool = False,
    callers: tuple[str, ...] = (),
) -> StepCost:
    """Replay ``Y``, ``R``, ``S`` through ``elf`` on ``board``, counting every direct call of the function ``symbol``
    (e.g. ``gl_fmaf`` on a soft-float core) from its entry to its return, callees included (``each``: every call's
    count too, in :attr:`StepCost.each`; ``callers``: only the calls made in those functions, e.g. the step's and not
    the start-up checks', which run with interrupts unmasked)."""
    with tempfile.TemporaryDirectory(prefix="gainlink-cost-") as tmp:
        result = Path(tmp) / "count.txt"
        per_call = Path(tmp) / "each.txt" if each else None
        plugin = counter_plugin(elf, symbol=symbol, out=result, each=per_call, callers=callers)
        fwqemu.replay(elf, artifact, board=board, Y=Y, R=R, S=S, plugin=plugin, law=law)
        return read_count(result, each=per_call)


def counter_plugin(
    elf: Path, *, symbol: str, out: Path, each: Path | None = None, callers: tuple[str, ...] = ()
) -> list[str]:
    """The QEMU arguments that count every direct call of ``symbol`` in ``elf`` from its entry to its return, callees
    included (the plugin, built and cached), the totals written to ``out`` when QEMU exits (:func:`read_count`), and
    every call's count to ``each`` when given (``callers``: :func:`return_addresses`)."""
    sym = symbol_sizes(elf, (symbol,)).get(symbol)
    if sym is None:
        raise FirmwareError(f"{elf} has no {symbol} symbol")
    returns = return_addresses(elf, symbol, callers)
    if not returns:
        where = f" from {', '.join(callers)}" if callers else ""
        raise FirmwareError(f"{elf} never calls {symbol} directly{where}: no return address to close a count")
    lo, hi = sym["address"], sym["address"] + sym["size"]
    spec = [f"{build_plugin()}", f"lo={lo:#x}", f"hi={hi:#x}", f"entry={lo:#x}", f"out={out}"]
    spec += [f"ret={r:#x}" for r in returns]
    if each is not None:
        spec.append(f"each={each}")
    return ["-plugin", ",".join(spec)]


def read_count(out: Path, each: Path | None = None) -> StepCost:
    """The counts the plugin wrote to ``out`` (and every call's to ``each``, :func:`counter_plugin`) when QEMU
    exited."""
    try:
        text = out.read_text()
    except OSError:
        raise FirmwareError("QEMU exited without the instruction counter's totals (the plugin did not run)") from None
    fields = {k: int(v) for k, v in (item.split("=") for item in text.split())}
    return StepCost(
        instructions=fields["insns"],
        calls=fields["calls"],
        own=fields["own"],
        cheapest=fields["min"],
        dearest=fields["max"],
        each=tuple(int(v) for v in each.read_text().split()) if each is not None else (),
    )


def law_macs(artifact: Artifact) -> int:
    """Multiply-accumulates of one step of the law as docs/design.md writes it ("The control law"): matrix-vector
    products."""
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
