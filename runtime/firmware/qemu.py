"""Running a Cortex-M image under ``qemu-system-arm``: replay through semihosting files.

The image (``firmware/ports/cortex-m/main.c``, one main for every law) reads ``gl_in.bin`` and writes ``gl_out.bin``
in QEMU's working directory: a header, then one sample in per record and one record out (the law's record,
:mod:`gainlink.shipping.records`: the same dtype the host bindings read). Every QEMU is started with stdin from
/dev/null, wrapped in ``timeout`` and killed in ``finally``; its exit status is the image's semihosting exit code.
"""

from __future__ import annotations

import logging
import shutil
import struct
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FirmwareError, ToolchainError
from ..shipping import records
from ..shipping.law_c import law_ids

log = logging.getLogger(__name__)

IN_MAGIC = 0x32494C47  # "GLI2"
OUT_MAGIC = 0x324F4C47  # "GLO2"
MAX_BLOCK = 64
TAG_STEP, TAG_IDLE, TAG_STAGE, TAG_RESET = records.TAG_STEP, records.TAG_IDLE, records.TAG_STAGE, records.TAG_RESET

EXIT_CODES = {
    0: "ok",
    1: "malformed input stream header",
    2: "semihosting I/O error or short read",
    4: "built-in gain set rejected by gl_law_init",
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


def encode_input(
    artifact: Any,
    Y: np.ndarray,
    R: np.ndarray | None = None,
    S: np.ndarray | None = None,
    *,
    block: int = MAX_BLOCK,
    watchdog_periods: int = 10,
    tags: np.ndarray | None = None,
) -> bytes:
    """The ``gl_in.bin`` stream for samples ``Y`` (N, p), references ``R`` (N, q) and external scheduling signals
    ``S`` (N, e) of ``artifact``'s law (cast to float32; missing ones zero), each record a step unless ``tags`` says
    otherwise (:data:`TAG_IDLE`, :data:`TAG_STAGE`, :data:`TAG_RESET`)."""
    rec = records.samples(artifact, Y, R, S, tags=tags)
    N = rec.size
    return struct.pack("<4I", IN_MAGIC, N, block, watchdog_periods) + rec.tobytes()


def output_header(artifact: Any, *, law: str | None = None) -> tuple[int, ...]:
    """The words 2..7 of the image's output header for ``artifact`` (running ``law``, default its own): the law's
    HEARTBEAT id and the dimensions n, m, p, q, e."""
    return (law_ids(artifact, law=law), *records.dims(artifact))


def decode_output(blob: bytes, artifact: Any, *, law: str | None = None) -> np.ndarray:
    """Parse ``gl_out.bin`` of an image of ``artifact`` (running ``law``, default its own): its records."""
    if len(blob) < 32:
        raise FirmwareError("firmware output stream is truncated (no header)")
    magic, count, *shape = struct.unpack("<8I", blob[:32])
    if magic != OUT_MAGIC or tuple(shape) != output_header(artifact, law=law):
        raise FirmwareError("firmware output stream has a bad header (image built for another artifact or law?)")
    rec = np.frombuffer(blob[32:], dtype=records.layout(artifact, law=law).dtype)
    if rec.shape[0] != count:
        raise FirmwareError(f"firmware wrote {rec.shape[0]} of {count} records")
    return rec


def replay(
    elf: Path,
    artifact: Any,
    *,
    board: str,
    Y: np.ndarray,
    R: np.ndarray | None = None,
    S: np.ndarray | None = None,
    tags: np.ndarray | None = None,
    watchdog_periods: int = 10,
    plugin: list[str] | None = None,
    stage_sets: list[bytes] | None = None,
    law: str | None = None,
) -> np.ndarray:
    """Run samples through the image ``elf`` of ``artifact`` in QEMU (semihosting file I/O); return its records
    (:func:`gainlink.shipping.records.layout`; ``law``: the law the image runs when it is not the artifact's own, a
    baseline built with ``GL_LAW``).

    ``stage_sets[K]`` is the raw ``gl_law_gains_t`` the K-th record tagged :data:`TAG_STAGE` stages.
    """
    blob = encode_input(artifact, Y, R, S, watchdog_periods=watchdog_periods, tags=tags)
    N = int(np.asarray(Y).reshape(-1, artifact.p).shape[0])
    with tempfile.TemporaryDirectory(prefix="gainlink-qemu-") as tmp:
        work = Path(tmp)
        (work / "gl_in.bin").write_bytes(blob)
        for k, gains in enumerate(stage_sets or []):
            (work / f"gl_stage{k}.bin").write_bytes(gains)
        res = run_image(elf, board=board, cwd=work, timeout_s=20.0 + N / 5000.0, plugin=plugin)
        if res.returncode != 0:
            raise FirmwareError(f"firmware image in QEMU ({board}) failed: {res.meaning}")
        out = (work / "gl_out.bin").read_bytes()
    return decode_output(out, artifact, law=law)
