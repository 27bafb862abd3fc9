"""Running the fixed-point C (``firmware/src/gl_fixed.c``) of a fixed-point artifact: the host library through
ctypes, the Cortex-M image under QEMU, and the instructions of its step.

Both write one record per step (``firmware/src/gl_fixed_record.h``): the flags, saturation, clip and overflow
masks, the command words ``U``, the unsaturated commands ``V``, the estimate ``XH``, the integrators ``Z`` and
the float commands ``u``. :class:`FixedRun` holds them as arrays; the reference is
:class:`gainlink.proof.fixed_law.FixedPointLoop`, bit for bit.
"""

from __future__ import annotations

import ctypes
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from ..shipping.artifact import Artifact
from ..shipping.codegen_fixed import is_fixed
from . import qemu as fwqemu
from . import targets as _targets
from .build import BuildResult, build
from .cost import StepCost, build_plugin, return_addresses
from .size import symbol_sizes

OUT_MAGIC = 0x31464C47  # "GLF1"
STEP_SYMBOL = "gl_fixed_step"
FAULT, CLIPPED, OVERFLOW = 1, 2, 4
GL_OK, GL_SATURATED, GL_ERR_NANINF = 0, 1, -2  # gl_status_t: the float loop's status codes


def step_status(flags: int, sat: int) -> int:
    """The float loop's status (gl_status_t) for a fixed-point step: refused (fault), saturated, or done."""
    if flags & FAULT:
        return GL_ERR_NANINF
    return GL_SATURATED if sat else GL_OK


OVERFLOW_BITS = {"dY": 1, "V": 2, "dU": 4, "Uv-V": 8, "Z": 16, "XH": 32}  # GL_FX_OVF_* of gl_fixed.h
# Replay and PIL build the tree without the float image's bus nodes (the fixed image never carries them): the
# float replay image's tree (gainlink.firmware.build.replay_image), built once for both.
REPLAY_OPTIONS = {"GL_IMAGE_SERVE": "OFF"}


def record_dtype(a: Artifact) -> np.dtype:
    """One output record of the fixed-point C for ``a``'s dimensions."""
    m, n, qa = a.m, a.n, max(a.q, 1)
    return np.dtype(
        [
            ("flags", "<u4"),
            ("sat", "<u4"),
            ("clip", "<u4"),
            ("overflow", "<u4"),
            ("U", "<i4", (m,)),
            ("V", "<i4", (m,)),
            ("XH", "<i4", (n,)),
            ("Z", "<i4", (qa,)),
            ("u", "<f4", (m,)),
        ]
    )


@dataclass(frozen=True)
class FixedRun:
    """What the fixed-point C did, step by step (N rows): command words ``U`` (N, m), unsaturated commands ``V``,
    estimate ``XH`` (N, n) and integrators ``Z`` (N, q) after each step, float commands ``u``, and the bit masks
    ``flags`` (GL_FX_FAULT 1, GL_FX_CLIPPED 2, GL_FX_OVERFLOW 4), ``sat`` (inputs at a limit), ``clip`` (samples,
    then references, clipped to their ranges) and ``overflow`` (:data:`OVERFLOW_BITS`)."""

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
    if not is_fixed(a):
        raise FirmwareError(f"artifact {a.name} is not a fixed-point design (numeric float32): no fixed-point C")


def _inputs(a: Artifact, Y, R) -> tuple[np.ndarray, np.ndarray]:
    Y = np.ascontiguousarray(np.asarray(Y, dtype=np.float32).reshape(-1, a.p))
    Rq = np.zeros((Y.shape[0], max(a.q, 1)), dtype=np.float32)
    if a.q:
        Rq[:, : a.q] = np.asarray(R, dtype=np.float32).reshape(Y.shape[0], a.q)
    return Y, np.ascontiguousarray(Rq)


def host_library(a: Artifact, *, options: dict | None = None, build_root: Path | None = None) -> Path:
    """Build (cached) the host firmware of fixed-point artifact ``a``; the path of ``libgainlink_fixed_host.so``.
    ``options``: extra CMake cache entries (e.g. ``{"GL_FIXED_UNROLLED": "OFF"}``: the generic loop)."""
    require_fixed(a)
    res = build(a, target="host", options=options, build_root=build_root, only="gainlink_fixed_host")
    return res.build_dir / "libgainlink_fixed_host.so"


def run_host(a: Artifact, Y, R=None, *, options: dict | None = None, build_root: Path | None = None) -> FixedRun:
    """Run samples ``Y`` (N, p) and references ``R`` (N, q) through the host build, from the initial state."""
    lib = ctypes.CDLL(str(host_library(a, options=options, build_root=build_root)))
    dtype = record_dtype(a)
    if lib.gl_fixed_host_record_words() * 4 != dtype.itemsize:
        raise FirmwareError("the host fixed-point library's record does not match this artifact")
    Yf, Rf = _inputs(a, Y, R)
    out = np.zeros(Yf.shape[0], dtype=dtype)
    lib.gl_fixed_host_run(
        Yf.ctypes.data_as(ctypes.c_void_p),
        Rf.ctypes.data_as(ctypes.c_void_p),
        ctypes.c_uint32(Yf.shape[0]),
        out.ctypes.data_as(ctypes.c_void_p),
    )
    return FixedRun.from_records(out, a.q)


def image(a: Artifact, *, target: str, board: str | None = None, options: dict | None = None) -> tuple[Path, str]:
    """Build (cached) the fixed-point image of ``a`` for a Cortex-M ``target``; its ELF and the QEMU board."""
    require_fixed(a)
    platform = _targets.resolve_cortex_m(target, board)
    res: BuildResult = build(a, target=platform.target.name, board=platform.board.name, options=options)
    return res.build_dir / "gainlink_fixed_image.elf", platform.board.name


def _decode(blob: bytes, a: Artifact) -> np.ndarray:
    if len(blob) < 32:
        raise FirmwareError("fixed-point image output is truncated (no header)")
    magic, count, n, m, p, q, _, _ = struct.unpack("<8I", blob[:32])
    if magic != OUT_MAGIC or (n, m, p, q) != (a.n, a.m, a.p, a.q):
        raise FirmwareError("fixed-point image output has a bad header (image built for another artifact?)")
    rec = np.frombuffer(blob[32:], dtype=record_dtype(a))
    if rec.shape[0] != count:
        raise FirmwareError(f"fixed-point image wrote {rec.shape[0]} of {count} records")
    return rec


def replay_image(elf: Path, a: Artifact, Y, R=None, *, board: str, plugin: list[str] | None = None) -> FixedRun:
    """Run samples through the fixed-point image ``elf`` in QEMU on ``board`` (semihosting files)."""
    Yf, Rf = _inputs(a, Y, R)
    blob = fwqemu.encode_input(Yf, Rf[:, : a.q] if a.q else None, n=a.n, m=a.m, p=a.p, q=a.q)
    with tempfile.TemporaryDirectory(prefix="gainlink-fixed-") as tmp:
        work = Path(tmp)
        (work / "gl_in.bin").write_bytes(blob)
        res = fwqemu.run_image(elf, board=board, cwd=work, timeout_s=20.0 + Yf.shape[0] / 5000.0, plugin=plugin)
        if res.returncode != 0:
            raise FirmwareError(f"fixed-point image in QEMU ({board}) failed: {res.meaning}")
        rec = _decode((work / "gl_out.bin").read_bytes(), a)
    return FixedRun.from_records(rec, a.q)


def run_qemu(a: Artifact, Y, R=None, *, target: str, board: str | None = None) -> FixedRun:
    """Build (cached) and replay the fixed-point image of ``a`` on ``target`` under QEMU."""
    elf, board_name = image(a, target=target, board=board, options=REPLAY_OPTIONS)
    return replay_image(elf, a, Y, R, board=board_name)


def count_step_instructions(elf: Path, a: Artifact, Y, R=None, *, board: str, symbol: str = STEP_SYMBOL) -> StepCost:
    """Instructions of every ``gl_fixed_step`` call (or of another function ``symbol``) over a replay, callees
    included (as :func:`gainlink.firmware.cost.count_calls` for the float step)."""
    sym = symbol_sizes(elf, (symbol,)).get(symbol)
    returns = return_addresses(elf, symbol)
    if sym is None or not returns:
        raise FirmwareError(f"{elf} has no direct call of {symbol}")
    lo, hi = sym["address"], sym["address"] + sym["size"]
    with tempfile.TemporaryDirectory(prefix="gainlink-cost-") as tmp:
        result = Path(tmp) / "count.txt"
        spec = [f"{build_plugin()}", f"lo={lo:#x}", f"hi={hi:#x}", f"entry={lo:#x}", f"out={result}"]
        spec += [f"ret={r:#x}" for r in returns]
        replay_image(elf, a, Y, R, board=board, plugin=["-plugin", ",".join(spec)])
        fields = {k: int(v) for k, v in (item.split("=") for item in result.read_text().split())}
    return StepCost(
        instructions=fields["insns"],
        calls=fields["calls"],
        own=fields["own"],
        cheapest=fields["min"],
        dearest=fields["max"],
    )
