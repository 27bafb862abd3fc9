"""The scheduled image under ``qemu-system-arm`` (``firmware/ports/cortex-m/main_sched.c``): replay through
semihosting files, as :mod:`gainlink.firmware.qemu` does for the unscheduled loop.

in:  ``{'GLS1', count, block, 0}`` then per step ``{float y[p], float r[q], float s[max(e, 1)]}``;
out: ``{'GLT1', count, n, m, p, q, npts, e}`` then per step ``{int32 status, uint32 sat, uint32 sflags,
float u[m], float state[n + m + p + q + 3]}`` (the state of ``gl_sched_state`` after the step).
"""

from __future__ import annotations

import struct
import tempfile
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from .qemu import MAX_BLOCK, run_image

IN_MAGIC = 0x31534C47  # "GLS1"
OUT_MAGIC = 0x31544C47  # "GLT1"


def record_dtypes(*, n: int, m: int, p: int, q: int, e: int) -> tuple[np.dtype, np.dtype]:
    """numpy dtypes of one input and one output record of the scheduled image's stream."""
    din = np.dtype([("y", "<f4", (p,)), ("r", "<f4", (q,)), ("s", "<f4", (max(e, 1),))])
    dout = np.dtype([("status", "<i4"), ("sat", "<u4"), ("sflags", "<u4"), ("u", "<f4", (m,)),
                     ("state", "<f4", (n + m + p + q + 3,))])  # fmt: skip
    return din, dout


def encode_input(Y, R, S, *, dims: dict, block: int = MAX_BLOCK) -> bytes:
    """The ``gl_in.bin`` stream for samples ``Y`` (N, p), ``R`` (N, q), ``S`` (N, e) (cast to float32)."""
    din, _ = record_dtypes(**dims)
    p, q, e = dims["p"], dims["q"], dims["e"]
    with np.errstate(over="ignore"):
        Y = np.asarray(Y, dtype=np.float64).reshape(-1, p)
        N = Y.shape[0]
        rec = np.zeros(N, dtype=din)
        rec["y"] = Y.astype(np.float32)
        rec["r"] = np.asarray(R, dtype=np.float64).reshape(N, q).astype(np.float32)
        if e > 0:
            rec["s"] = np.asarray(S, dtype=np.float64).reshape(N, e).astype(np.float32)
    return struct.pack("<4I", IN_MAGIC, N, block, 0) + rec.tobytes()


def decode_output(blob: bytes, *, dims: dict, npts: int) -> np.ndarray:
    """Parse the scheduled image's ``gl_out.bin`` into its records."""
    if len(blob) < 32:
        raise FirmwareError("firmware output stream is truncated (no header)")
    magic, count, *shape = struct.unpack("<8I", blob[:32])
    d = dims
    if magic != OUT_MAGIC or tuple(shape) != (d["n"], d["m"], d["p"], d["q"], npts, d["e"]):
        raise FirmwareError("firmware output stream has a bad header (image built for another artifact?)")
    rec = np.frombuffer(blob[32:], dtype=record_dtypes(**dims)[1])
    if rec.shape[0] != count:
        raise FirmwareError(f"firmware wrote {rec.shape[0]} of {count} records")
    return rec


def replay(elf: Path, *, board: str, dims: dict, npts: int, Y, R, S, plugin: list[str] | None = None) -> np.ndarray:
    """Run samples through the scheduled image in QEMU; return its output records.

    ``dims`` holds ``n m p q e`` of the artifact the image was built for.
    """
    blob = encode_input(Y, R, S, dims=dims)
    N = int(np.asarray(Y).reshape(-1, dims["p"]).shape[0])
    with tempfile.TemporaryDirectory(prefix="gainlink-qemu-") as tmp:
        work = Path(tmp)
        (work / "gl_in.bin").write_bytes(blob)
        res = run_image(elf, board=board, cwd=work, timeout_s=20.0 + N / 5000.0, plugin=plugin)
        if res.returncode != 0:
            raise FirmwareError(f"scheduled firmware image in QEMU ({board}) failed: {res.meaning}")
        out = (work / "gl_out.bin").read_bytes()
    return decode_output(out, dims=dims, npts=npts)
