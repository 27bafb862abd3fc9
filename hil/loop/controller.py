"""The controller peer process: the firmware's host app, the Python reference node, or the Cortex-M4F image
in QEMU, started and stopped by the bridge.

The bridge waits for the peer's ``ready`` line before the first sample, can pause it (the "silent
controller" fault) and always ends it: SIGTERM, then SIGKILL after a grace period. The image in QEMU
(:func:`qemu_peer`, a :class:`gainlink.firmware.uart.QemuUart`) answers the same calls; its ready line
comes from its UART.
"""

from __future__ import annotations

import json
import logging
import os
import re
import selectors
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from gainlink.errors import FirmwareError
from gainlink.firmware.capture import StderrCapture

from ..links.can_firmware import firmware_can_executable
from .scenario import CONTROLLERS

log = logging.getLogger(__name__)

#: Upper bound of a QEMU peer's life beyond the run's own duration (QEMU is stopped at the end anyway).
QEMU_SLACK_S = 600.0


def qemu_peer(*, artifact: Any, transport: Any, board: str, elf: Path | None, duration_s: float) -> Any:
    """The Cortex-M image in QEMU serving ``transport``'s link on its UART (not started yet).

    ``elf`` is a prebuilt image; by default the image of ``gainlink firmware build --board BOARD`` (the
    board's core) for ``artifact`` (built and cached).
    """
    from gainlink.firmware.build import build
    from gainlink.firmware.targets import BOARDS
    from gainlink.firmware.uart import QemuUart
    from gainlink.shipping.law_c import law_name

    protocol, host, port, options = transport.qemu_serve()
    refusal = BOARDS[board].serving_refusal(protocol, law=law_name(artifact))
    if refusal is not None:
        raise FirmwareError(refusal)
    if elf is None:  # the artifact's image serves its law (ports/cortex-m/main.c, one main for every law)
        elf = build(artifact, target=BOARDS[board].core, board=board).files["elf"]
    elif not Path(elf).is_file():
        raise FirmwareError(f"firmware image {elf} not found")
    return QemuUart(
        Path(elf),
        board=board,
        protocol=protocol,
        host=host,
        port=port,
        options=options,
        lifetime_s=QEMU_SLACK_S + 4.0 * duration_s,
        signing_key=getattr(transport, "signing_key_bytes", None),
    )


def controller_argv(
    kind: str, *, artifact: Any, artifact_path: Path, transport: Any, executable: Path | None = None
) -> list[str]:
    """The command line of the controller peer ``kind`` for this transport.

    For ``firmware``: ``executable`` (a prebuilt app named by the scenario) if given, else the
    transport's own ``firmware_executable(artifact)`` if it has one (e.g. MAVLink), else the CAN app.
    """
    if kind == "firmware":
        if executable is not None:
            if not Path(executable).is_file() or not os.access(executable, os.X_OK):
                raise FirmwareError(f"firmware executable {executable} not found or not executable")
            return [str(executable), *transport.controller_argv()]
        build_app = getattr(transport, "firmware_executable", firmware_can_executable)
        return [str(build_app(artifact)), *transport.controller_argv()]
    if kind == "reference":
        if hasattr(transport, "reference_argv"):  # e.g. MAVLink: the transport names its own reference node
            return transport.reference_argv(artifact_path)
        return [
            sys.executable,
            "-m",
            "gainlink.hil.links.can_node",
            str(artifact_path),
            "--config",
            json.dumps(transport.config),
        ]
    if kind == "qemu":
        raise FirmwareError('controller = "qemu" is not a host process: the bridge starts it with qemu_peer()')
    raise FirmwareError(f"unknown controller {kind!r} (choose from {', '.join(CONTROLLERS)})")


class ControllerProcess:
    """A peer process with a ready handshake and a bounded stop.

    Parameters
    ----------
    argv : list of str
        Command line.
    ready_timeout : float
        Seconds to wait for the ``ready`` line.
    """

    def __init__(self, argv: list[str], *, ready_timeout: float = 20.0) -> None:
        self.argv = list(argv)
        self.ready_timeout = ready_timeout
        self.proc: subprocess.Popen | None = None
        self._stderr: StderrCapture | None = None
        self.ready_line = ""
        self.paused = False

    def check_artifact(self, sha256: str) -> None:
        """Fail unless the ready line names the artifact ``sha256`` (a firmware built for other gains), speaks this
        gainlink's wire format (``wire=4``) and, for a MAVLink node, says that it runs that artifact's set
        (``gains=artifact``, not a persisted one)."""
        from gainlink.firmware.uart import refuse_other_wire, refuse_persisted

        m = re.search(r"sha256:([0-9a-f]{64})", self.ready_line)
        if m is None or m.group(1) != sha256:
            found = m.group(1)[:16] if m else "unknown"
            self.stop()
            raise FirmwareError(
                f"controller {Path(self.argv[0]).name} runs artifact sha256:{found}..., "
                f"not the scenario's sha256:{sha256[:16]}..."
            )
        what = f"controller {Path(self.argv[0]).name}"
        refuse_other_wire(self.ready_line, what=what, stop=self.stop)
        refuse_persisted(self.ready_line, what=what, stop=self.stop)

    def start(self) -> None:
        """Start the process and wait for its ready line; :class:`FirmwareError` if it dies or stays silent."""
        try:
            self.proc = subprocess.Popen(
                self.argv,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                start_new_session=True,
            )
        except OSError as exc:
            raise FirmwareError(f"cannot start controller {self.argv[0]}: {exc.strerror}") from None
        self._stderr = StderrCapture(self.proc.stderr)  # drained at once, kept bounded (head + tail)
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + self.ready_timeout
        buf = b""
        try:
            while b"\n" not in buf:
                left = deadline - time.monotonic()
                if left <= 0:
                    self.stop()
                    raise FirmwareError(
                        f"controller {Path(self.argv[0]).name} sent no ready line within "
                        f"{self.ready_timeout:.0f} s{self._stderr_hint()}"
                    )
                if not sel.select(timeout=left):
                    continue
                chunk = os.read(self.proc.stdout.fileno(), 4096)
                if not chunk:
                    code = self.proc.wait(timeout=5)
                    self._stderr.join()
                    raise FirmwareError(
                        f"controller {Path(self.argv[0]).name} exited with status {code} before "
                        f"it was ready{self._stderr_hint()}"
                    )
                buf += chunk
        finally:
            sel.close()
        self.ready_line = buf.split(b"\n", 1)[0].decode(errors="replace")
        log.debug("controller ready: %s", self.ready_line)
        # Keep reading whatever the peer prints later, so a chatty peer never blocks on a full pipe.
        threading.Thread(target=self._drain, args=(self.proc.stdout,), daemon=True).start()

    @staticmethod
    def _drain(stream: Any) -> None:
        try:
            while stream.read(65536):
                pass
        except (OSError, ValueError):
            pass

    def _stderr_hint(self) -> str:
        text = self.stderr_tail()
        return f": {text}" if text else ""

    def stderr_tail(self, lines: int = 3) -> str:
        """The last lines the process wrote to stderr, joined into one line."""
        return "" if self._stderr is None else " | ".join(self._stderr.tail_lines(lines))

    def counters(self) -> dict[str, int]:
        """The ``key=value`` counters of the exit summary the firmware apps write (after :meth:`stop`)."""
        return {} if self._stderr is None else self._stderr.counters()

    def stderr_bytes(self) -> dict[str, int]:
        """How much the process wrote to stderr and how much of it was not kept (the capture is bounded)."""
        if self._stderr is None:
            return {"total": 0, "not_kept": 0}
        return {"total": self._stderr.total_bytes, "not_kept": self._stderr.dropped_bytes}

    def exit_status(self) -> int | None:
        """The exit status when the process has ended, else ``None``."""
        return None if self.proc is None else self.proc.poll()

    def pause(self) -> None:
        """Freeze the process (SIGSTOP): the controller goes silent."""
        if self.proc is not None and self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGSTOP)
            self.paused = True

    def kill(self) -> None:
        """Kill the process (SIGKILL): the controller crashes."""
        if self.proc is not None and self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)

    def stop(self, *, grace: float = 2.0) -> int | None:
        """End the process (SIGCONT+SIGTERM, SIGKILL after ``grace`` s); returns its exit status."""
        proc = self.proc
        if proc is None:
            return None
        if proc.poll() is None:
            try:
                if self.paused:
                    os.kill(proc.pid, signal.SIGCONT)
                proc.terminate()
                proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=grace)
            except ProcessLookupError:
                pass
        if proc.stdout is not None:
            proc.stdout.close()
        if self._stderr is not None:
            self._stderr.join()  # its exit summary is in
        return proc.returncode

    def close(self) -> None:
        """Stop the process."""
        self.stop()
