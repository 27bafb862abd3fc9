"""Running the fixed-point C (``firmware/src/gl_fixed.c``) of a fixed-point artifact: the host library through
ctypes, the Cortex-M image under QEMU, and the instructions of its step.

A fixed-point artifact's build runs its integer law (``firmware/include/gainlink/gl_law.h``): the host library, the
host executable and the image are the same ones every law has, and write the law's record
(:func:`gainlink.shipping.records.layout`): status, flags (the one flag table), saturation, the float commands, the
command words ``U``, the unsaturated commands ``V``, the estimate ``XH``, the integrators ``Z`` and the clip and
overflow masks. :class:`FixedRun` holds them as arrays; the reference is
:class:`gainlink.laws.fixed.model.FixedPointLoop`, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import FirmwareError
from ...firmware import qemu as fwqemu
from ...firmware import targets as _targets
from ...firmware.build import BuildResult, build
from ...firmware.cost import StepCost, count_step_instructions
from ...firmware.host import HostLaw
from ...shipping import flags as status_flags
from ...shipping import records
from ...shipping.artifact import Artifact
from ...shipping.law_c import law_name
from .codegen import INTEGER_LAWS

FAULT, CLIPPED, OVERFLOW = status_flags.FAULT, status_flags.CLIPPED, status_flags.OVERFLOW
OVERFLOW_BITS = {"dY": 1, "V": 2, "dU": 4, "Uv-V": 8, "Z": 16, "XH": 32}  # GL_FX_OVF_* of gl_fixed.h
# Replay and PIL build the image without the bus nodes (GL_IMAGE_SERVE=OFF): the law's unrolled variant, the one the
# instruction count covers.
REPLAY_OPTIONS = {"GL_IMAGE_SERVE": "OFF"}


def record_dtype(a: Artifact) -> np.dtype:
    """One output record of the fixed-point C for ``a`` (the law's record, :func:`gainlink.shipping.records.layout`)."""
    return records.layout(a).dtype


@dataclass(frozen=True)
class FixedRun:
    """What the fixed-point C did, step by step (N rows): command words ``U`` (N, m), unsaturated commands ``V``,
    estimate ``XH`` (N, n) and integrators ``Z`` (N, q) after each step, float commands ``u``, and the bit masks
    ``flags`` (the one flag table, :mod:`gainlink.shipping.flags`: :data:`FAULT`, :data:`CLIPPED`,
    :data:`OVERFLOW`), ``sat`` (inputs at a limit), ``clip`` (samples, then references, clipped to their ranges) and
    ``overflow`` (:data:`OVERFLOW_BITS`)."""

    U: np.ndarray
    V: np.ndarray
    XH: np.ndarray
    Z: np.ndarray
    u: np.ndarray
    flags: np.ndarray
    sat: np.ndarray
    clip: np.ndarray
    overflow: np.ndarray

    @classmethod
    def from_records(cls, rec: np.ndarray, q: int) -> FixedRun:
        """From the records the C wrote."""
        return cls(
            U=rec["U"].astype(np.int64),
            V=rec["V"].astype(np.int64),
            XH=rec["XH"].astype(np.int64),
            Z=rec["Z"][:, :q].astype(np.int64),
            u=rec["u"].copy(),
            flags=rec["flags"].copy(),
            sat=rec["sat"].copy(),
            clip=rec["clip"].copy(),
            overflow=rec["overflow"].copy(),
        )


def require_fixed(a: Artifact) -> None:
    """Refuse, in one line, an artifact that is not a fixed-point design."""
    if law_name(a) not in INTEGER_LAWS:
        raise FirmwareError(f"artifact {a.name} is not a fixed-point design (numeric float32): no fixed-point C")


def host_library(a: Artifact, *, options: dict | None = None, build_root: Path | None = None) -> Path:
    """Build (cached) the host firmware of fixed-point artifact ``a``; the path of its ``libgainlink_host.so`` (the
    integer law's). ``options``: extra CMake cache entries (e.g. ``{"GL_FIXED_UNROLLED": "OFF"}``: the generic
    loop)."""
    require_fixed(a)
    return build(a, target="host", options=options, build_root=build_root, only="gainlink_host").files["shared"]


def run_host(a: Artifact, Y, R=None, *, options: dict | None = None, build_root: Path | None = None) -> FixedRun:
    """Run samples ``Y`` (N, p) and references ``R`` (N, q) through the host build, from the initial state."""
    host = HostLaw(a, library=host_library(a, options=options, build_root=build_root))
    return FixedRun.from_records(host.run(Y, R), a.q)


def image(a: Artifact, *, target: str, board: str | None = None, options: dict | None = None) -> tuple[Path, str]:
    """Build (cached) the image of fixed-point artifact ``a`` for a Cortex-M ``target``; its ELF and the QEMU board."""
    require_fixed(a)
    platform = _targets.resolve_cortex_m(target, board)
    res: BuildResult = build(a, target=platform.target.name, board=platform.board.name, options=options)
    return res.files["elf"], platform.board.name


def replay_image(elf: Path, a: Artifact, Y, R=None, *, board: str, plugin: list[str] | None = None) -> FixedRun:
    """Run samples through the fixed-point image ``elf`` in QEMU on ``board`` (semihosting files)."""
    rec = fwqemu.replay(elf, a, board=board, Y=Y, R=R if a.q else None, plugin=plugin)
    return FixedRun.from_records(rec, a.q)


def run_qemu(a: Artifact, Y, R=None, *, target: str, board: str | None = None) -> FixedRun:
    """Build (cached) and replay the fixed-point image of ``a`` on ``target`` under QEMU."""
    elf, board_name = image(a, target=target, board=board, options=REPLAY_OPTIONS)
    return replay_image(elf, a, Y, R, board=board_name)


def count_fixed_step_instructions(elf: Path, a: Artifact, Y, R=None, *, board: str) -> StepCost:
    """Instructions of every ``gl_fixed_step`` call over a replay, callees included
    (:func:`gainlink.firmware.cost.count_step_instructions`)."""
    return count_step_instructions(elf, a, Y=Y, R=R if a.q else None, board=board)
