"""Running the Cortex-M4F image under ``qemu-system-arm``: replay through semihosting files.

The image (see ``firmware/ports/cortex-m/main.c``) reads ``gl_in.bin`` and writes ``gl_out.bin`` in
QEMU's working directory. Every QEMU is started with stdin from /dev/null, wrapped in ``timeout``
and killed in ``finally``; its exit status is the image's semihosting exit code.
"""

from __future__ import annotations

import logging
import shutil
import struct
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FirmwareError, ToolchainError

log = logging.getLogger(__name__)

IN_MAGIC = 0x31494C47  # "GLI1"
OUT_MAGIC = 0x314F4C47  # "GLO1"
MAX_BLOCK = 64
TAG_STEP, TAG_IDLE, TAG_STAGE = 0, 1, 2

EXIT_CODES = {
    0: "ok",
    1: "malformed input stream header",
    2: "semihosting I/O error or short read",
    4: "built-in gain set rejected by gl_loop_init",
    8: "startup self-test: FPU not enabled",
    9: "CPU fault (HardFault/UsageFault)",
    124: "timed out",
}
EXIT_FPU = 8
EXIT_FAULT = 9


def qemu_binary() -> str:
    """Path of ``qemu-system-arm``."""
    path = shutil.which("qemu-system-arm")
    if path is None:
        raise ToolchainError("qemu-system-arm not found: install qemu-system-arm (make setup)")
    return path


def qemu_command(
    elf: Path,
    *,
    board: str,
    serial: str = "null",
    plugin: list[str] | None = None,
    semihosting_args: list[str] | None = None,
) -> list[str]:
    """The QEMU command line for ``elf`` on ``board`` (semihosting on, no display, no monitor).

    ``semihosting_args`` become the image's command line (``arg=`` of ``-semihosting-config``; no commas).
    """
    config = "enable=on,target=native" + "".join(f",arg={a}" for a in semihosting_args or [])
    cmd = [
        qemu_binary(),
        "-M",
        board,
        "-kernel",
        str(elf),
        "-nodefaults",
        "-nic",
        "none",
        "-display",
        "none",
        "-monitor",
        "none",
        "-serial",
        serial,
        "-semihosting-config",
        config,
    ]
    if plugin:
        cmd += plugin
    return cmd


@dataclass(frozen=True)
class QemuRun:
    """How a QEMU run ended: the image's exit code and what it printed on the UART."""

    returncode: int
    uart: str

    @property
    def meaning(self) -> str:
        """The exit code in words."""
        return EXIT_CODES.get(self.returncode, f"exit status {self.returncode}")


def run_image(elf: Path, *, board: str, cwd: Path, timeout_s: float = 20.0, plugin: list[str] | None = None) -> QemuRun:
    """Boot ``elf`` in QEMU with ``cwd`` as the semihosting directory and wait for it to exit.

    The UART goes to ``cwd/uart.log``. The process is wrapped in ``timeout`` and killed if still alive.
    """
    uart = cwd / "uart.log"
    cmd = ["timeout", "-k", "2", str(timeout_s)] + qemu_command(elf, board=board, serial=f"file:{uart}", plugin=plugin)
    log.debug("qemu: %s", " ".join(cmd))
    proc = subprocess.Popen(cmd, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        _out, err = proc.communicate(timeout=timeout_s + 5)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = uart.read_text("latin-1") if uart.exists() else ""
    if proc.returncode not in EXIT_CODES:
        log.debug("qemu stderr: %s", err.decode(errors="replace").strip())
    return QemuRun(returncode=proc.returncode, uart=text)


def record_dtypes(*, n: int, m: int, p: int, q: int) -> tuple[np.dtype, np.dtype]:
    """numpy dtypes of one input and one output record of the image's stream."""
    qa = max(q, 1)
    din = np.dtype([("tag", "<u4"), ("y", "<f4", (p,)), ("r", "<f4", (qa,))])
    dout = np.dtype([("status", "<i4"), ("sat", "<u4"), ("u", "<f4", (m,)), ("xh", "<f4", (n,)), ("z", "<f4", (qa,))])
    return din, dout


def encode_input(
    Y: np.ndarray,
    R: np.ndarray | None,
    *,
    n: int,
    m: int,
    p: int,
    q: int,
    block: int = MAX_BLOCK,
    watchdog_periods: int = 10,
    tags: np.ndarray | None = None,
) -> bytes:
    """The ``gl_in.bin`` stream for samples ``Y`` (N, p), ``R`` (N, q)."""
    din, _ = record_dtypes(n=n, m=m, p=p, q=q)
    Y = np.asarray(Y, dtype=np.float64).reshape(-1, p)
    N = Y.shape[0]
    rec = np.zeros(N, dtype=din)
    rec["y"] = Y.astype(np.float32)
    if q > 0:
        rec["r"] = np.asarray(R, dtype=np.float64).reshape(N, q).astype(np.float32)
    if tags is not None:
        rec["tag"] = tags
    return struct.pack("<4I", IN_MAGIC, N, block, watchdog_periods) + rec.tobytes()


def decode_output(blob: bytes, *, n: int, m: int, p: int, q: int) -> tuple[np.ndarray, int]:
    """Parse ``gl_out.bin``: the records and the checksum of the gain set that ran."""
    if len(blob) < 32:
        raise FirmwareError("firmware output stream is truncated (no header)")
    magic, count, nn, mm, pp, qq, crc, _ = struct.unpack("<8I", blob[:32])
    if magic != OUT_MAGIC or (nn, mm, pp, qq) != (n, m, p, q):
        raise FirmwareError("firmware output stream has a bad header (image built for another artifact?)")
    _, dout = record_dtypes(n=n, m=m, p=p, q=q)
    rec = np.frombuffer(blob[32:], dtype=dout)
    if rec.shape[0] != count:
        raise FirmwareError(f"firmware wrote {rec.shape[0]} of {count} records")
    return rec, crc


def replay(
    elf: Path,
    *,
    board: str,
    n: int,
    m: int,
    p: int,
    q: int,
    Y: np.ndarray,
    R: np.ndarray | None,
    tags: np.ndarray | None = None,
    watchdog_periods: int = 10,
    plugin: list[str] | None = None,
    stage_sets: list[bytes] | None = None,
) -> np.ndarray:
    """Run samples through the image in QEMU (semihosting file I/O); return the output records.

    ``stage_sets[K]`` is the raw ``gl_gains_t`` the K-th record tagged :data:`TAG_STAGE` stages.
    """
    blob = encode_input(Y, R, n=n, m=m, p=p, q=q, watchdog_periods=watchdog_periods, tags=tags)
    N = int(np.asarray(Y).reshape(-1, p).shape[0])
    with tempfile.TemporaryDirectory(prefix="gainlink-qemu-") as tmp:
        work = Path(tmp)
        (work / "gl_in.bin").write_bytes(blob)
        for k, gains in enumerate(stage_sets or []):
            (work / f"gl_stage{k}.bin").write_bytes(gains)
        res = run_image(elf, board=board, cwd=work, timeout_s=20.0 + N / 5000.0, plugin=plugin)
        if res.returncode != 0:
            raise FirmwareError(f"firmware image in QEMU ({board}) failed: {res.meaning}")
        out = (work / "gl_out.bin").read_bytes()
    rec, _crc = decode_output(out, n=n, m=m, p=p, q=q)
    return rec
