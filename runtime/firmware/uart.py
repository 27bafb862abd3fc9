"""The Cortex-M4F image as a bus node on its UART, under ``qemu-system-arm``.

The image (``firmware/ports/cortex-m``) speaks MAVLink or slcan on its console UART when the simulator's
command line says ``serve mavlink`` / ``serve slcan`` (semihosting arguments). QEMU exposes that UART
as a TCP server socket, which pymavlink opens as ``tcp:HOST:PORT`` and pyserial (python-can's ``slcan``)
as ``socket://HOST:PORT``. :class:`QemuUart` starts QEMU, connects once to read the banner (the image
enables its UART before it prints it, so nothing sent afterwards is lost), closes that connection so
the client can connect, and always stops QEMU.

QEMU's working directory stands for the board's flash: the image keeps its committed gain set in
``gl_flash.txt`` there (and a signing key set over the UART in ``gl_key.bin``), so a restart with the same
``flash_dir`` reloads them.

Traps handled here (FIELD-NOTES): ``wait=on`` so no output is lost before the first connection, ``nodelay=on``
(Nagle costs ~100x), stdin from /dev/null. QEMU runs under ``timeout`` (``lifetime_s``; 0: no bound) in a
session of its own, signalled as a group; ``timeout`` gets SIGTERM when the thread that started it ends
(``PR_SET_PDEATHSIG``) and passes it on, so QEMU does not outlive a crashed caller.
"""

from __future__ import annotations

import ctypes
import logging
import os
import re
import selectors
import signal
import socket
import struct
import subprocess
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from ..errors import FirmwareError, TransportError
from ..shipping.flags import WIRE_VERSION
from .qemu import EXIT_CODES, qemu_command

log = logging.getLogger(__name__)

PROTOCOLS = ("mavlink", "slcan")
FLASH_FILE = "gl_flash.txt"
KEY_FILE = "gl_key.bin"
_PR_SET_PDEATHSIG = 1


def _term_with_parent() -> None:  # runs in the child between fork and exec
    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def tcp_endpoint(url: str, *, scheme: str = "tcp") -> tuple[str, int]:
    """``(host, port)`` of ``tcp:HOST:PORT`` (or ``socket://HOST:PORT`` with ``scheme="socket"``).

    Raises
    ------
    TransportError
        When ``url`` has another form (one line naming the expected one).
    """
    text = url[len("socket://") :] if scheme == "socket" and url.startswith("socket://") else None
    if scheme == "tcp" and url.startswith("tcp:"):
        text = url[len("tcp:") :]
    form = "tcp:HOST:PORT" if scheme == "tcp" else "socket://HOST:PORT"
    if text is None or text.count(":") != 1:
        raise TransportError(f"expected {form}, got {url!r}")
    host, port = text.split(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise TransportError(f"expected {form} with a port 1..65535, got {url!r}")
    return host, int(port)


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listens on right now (for tests and benchmarks)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def double_bits(value: float) -> str:
    """The 16 hex digits of an IEEE-754 double: how the image takes int16 scales (exactly, without strtod)."""
    return struct.pack(">d", float(value)).hex()


def scale_option(pairs: Sequence[tuple[float, float]]) -> str:
    """``F:O/F:O/...`` of ``(factor, offset)`` pairs as double bits (the image's ``meas=`` / ``cmd=``)."""
    return "/".join(f"{double_bits(f)}:{double_bits(o)}" for f, o in pairs)


def serve_arguments(protocol: str, options: Sequence[str] = ()) -> list[str]:
    """The semihosting arguments that make the image serve ``protocol`` with ``key=value`` options."""
    if protocol not in PROTOCOLS:
        raise FirmwareError(f"the image serves {' or '.join(PROTOCOLS)}, not {protocol!r}")
    for opt in options:
        if "," in opt or " " in opt or "=" not in opt:
            raise FirmwareError(f"image option {opt!r} must be key=value without spaces or commas")
    return ["gainlink", "serve", protocol, *options]


class QemuUart:
    """The image in QEMU serving ``protocol`` on its UART at ``tcp:host:port`` (a context manager).

    Parameters
    ----------
    elf : Path
        The image (``gainlink firmware build --target cortex-m4``).
    board : str
        ``mps2-an386`` or ``netduinoplus2``.
    protocol : {"mavlink", "slcan"}
        What the image speaks.
    host, port : str, int
        Where QEMU listens for the UART's client.
    options : sequence of str
        ``key=value`` options of the protocol (see ``firmware/ports/cortex-m/serve.h``).
    flash_dir : Path, optional
        QEMU's working directory, standing for the board's flash (kept across restarts when given;
        a temporary directory, removed at stop, otherwise).
    ready_timeout : float
        Seconds to wait for QEMU to listen and for the banner.
    lifetime_s : float
        Upper bound of QEMU's run time (``timeout``); 0 for none (a foreground run).
    signing_key : bytes, optional
        A MAVLink signing key (32 bytes) put in the image's flash before it starts (``gl_key.bin``).

    Attributes
    ----------
    banner : str
        ``gainlink NAME BOARD sha256:HEX``, the image's first line.
    ready_line : str
        The banner and the image's ``ready ...`` line, joined by a space.
    """

    def __init__(
        self,
        elf: Path,
        *,
        board: str,
        protocol: str,
        host: str = "127.0.0.1",
        port: int,
        options: Sequence[str] = (),
        flash_dir: Path | None = None,
        ready_timeout: float = 20.0,
        lifetime_s: float = 0.0,
        signing_key: bytes | None = None,
    ) -> None:
        self.elf, self.board, self.protocol = Path(elf), board, protocol
        self.host, self.port = host, int(port)
        self.ready_timeout = ready_timeout
        self._tmp = None if flash_dir is not None else tempfile.TemporaryDirectory(prefix="gainlink-flash-")
        self.flash_dir = Path(flash_dir) if flash_dir is not None else Path(self._tmp.name)
        serial = f"tcp:{host}:{self.port},server=on,wait=on,nodelay=on"
        self.argv = ["timeout", "-k", "2", f"{max(0.0, lifetime_s):g}"] + qemu_command(
            self.elf, board=board, serial=serial, semihosting_args=serve_arguments(protocol, options)
        )
        if signing_key is not None and len(signing_key) != 32:
            raise FirmwareError("a MAVLink signing key has 32 bytes")
        self.signing_key = signing_key
        self.proc: subprocess.Popen | None = None
        self._stderr = tempfile.TemporaryFile(mode="w+b")
        self.banner = ""
        self.ready_line = ""
        self.paused = False

    @property
    def url(self) -> str:
        """The UART as pymavlink opens it: ``tcp:HOST:PORT``."""
        return f"tcp:{self.host}:{self.port}"

    @property
    def channel(self) -> str:
        """The UART as pyserial (python-can ``slcan``) opens it: ``socket://HOST:PORT``."""
        return f"socket://{self.host}:{self.port}"

    def start(self) -> QemuUart:
        """Start QEMU, read the banner and the ready line, and leave the UART free for the client.

        Raises
        ------
        FirmwareError
            QEMU exits or stays silent, or the image refuses its options (its ``error:`` line).
        """
        self.flash_dir.mkdir(parents=True, exist_ok=True)
        if self.signing_key is not None:
            key_file = self.flash_dir / KEY_FILE
            key_file.write_bytes(self.signing_key)
            key_file.chmod(0o600)
        log.debug("qemu: %s", " ".join(self.argv))
        try:
            self.proc = subprocess.Popen(
                self.argv,
                cwd=self.flash_dir,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=self._stderr,
                start_new_session=True,
                preexec_fn=_term_with_parent,
            )
        except OSError as exc:
            raise FirmwareError(f"cannot start {self.argv[0]}: {exc.strerror}") from None
        try:
            lines = self._read_banner(time.monotonic() + self.ready_timeout)
        except BaseException:
            self.stop()
            raise
        self.banner, self.ready_line = lines[0], " ".join(lines)
        log.debug("image ready: %s", self.ready_line)
        return self

    def _connect(self, deadline: float) -> socket.socket:
        while True:
            try:
                return socket.create_connection((self.host, self.port), timeout=1.0)
            except OSError:
                if self.proc.poll() is not None:
                    raise FirmwareError(
                        f"QEMU exited with status {self.proc.returncode} before its UART listened{self._stderr_hint()}"
                    ) from None
                if time.monotonic() > deadline:
                    raise FirmwareError(
                        f"QEMU's UART at {self.url} did not listen within {self.ready_timeout:g} s"
                    ) from None
                time.sleep(0.02)

    def _read_banner(self, deadline: float) -> list[str]:
        sock = self._connect(deadline)
        buf = b""
        try:
            with selectors.DefaultSelector() as sel:
                sel.register(sock, selectors.EVENT_READ)
                while buf.count(b"\n") < 2:
                    left = deadline - time.monotonic()
                    if left <= 0 or not sel.select(timeout=left):
                        raise FirmwareError(
                            f"the image on {self.board} sent no ready line within "
                            f"{self.ready_timeout:g} s (UART so far: {buf[:120]!r})"
                        )
                    chunk = sock.recv(4096)
                    if not chunk:
                        self._wait_exit()
                        raise FirmwareError(self._exit_reason(buf))
                    buf += chunk
        finally:
            sock.close()
        lines = buf.decode("latin-1").split("\n")[:2]
        if lines[1].startswith("error: "):
            raise FirmwareError(self._exit_reason(buf))
        if not lines[0].startswith("gainlink ") or not lines[1].startswith(f"ready {self.protocol}"):
            raise FirmwareError(f"unexpected banner from the image: {' | '.join(lines)!r}")
        return lines

    def _wait_exit(self) -> None:
        try:
            self.proc.wait(timeout=2)
        except subprocess.TimeoutExpired:
            pass

    def _exit_reason(self, buf: bytes) -> str:
        text = buf.decode("latin-1")
        err = next((ln for ln in text.splitlines() if ln.startswith("error: ")), None)
        if err is not None:
            return f"the image refused its options: {err[len('error: ') :]}"
        code = self.proc.poll()
        meaning = EXIT_CODES.get(code, f"status {code}") if code is not None else "still running"
        return f"the image stopped before it was ready ({meaning}){self._stderr_hint()}"

    # -- the bridge's peer interface (as hil.loop.controller.ControllerProcess) -------------------------
    def check_artifact(self, sha256: str) -> None:
        """Fail unless the banner names the artifact ``sha256`` (an image built for other gains) and the image runs
        that artifact's set (not one persisted in its flash)."""
        m = re.search(r"sha256:([0-9a-f]{64})", self.banner)
        if m is None or m.group(1) != sha256:
            found = m.group(1)[:16] if m else "unknown"
            self.stop()
            raise FirmwareError(f"the image runs artifact sha256:{found}..., not sha256:{sha256[:16]}...")
        refuse_other_wire(self.ready_line, what="the image", stop=self.stop)
        refuse_persisted(self.ready_line, what="the image", stop=self.stop)

    def exit_status(self) -> int | None:
        """QEMU's exit status when it has ended (the image's semihosting exit code), else ``None``."""
        return None if self.proc is None else self.proc.poll()

    def _signal(self, sig: int) -> None:
        """Signal QEMU and its ``timeout`` (their own process group)."""
        if self.proc is not None and self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, sig)
            except ProcessLookupError:
                pass

    def pause(self) -> None:
        """Freeze QEMU (SIGSTOP): the image goes silent."""
        self._signal(signal.SIGSTOP)
        self.paused = True

    def kill(self) -> None:
        """Kill QEMU (SIGKILL): the board loses power."""
        self._signal(signal.SIGKILL)

    def stderr_tail(self, lines: int = 3) -> str:
        """QEMU's last stderr lines, joined into one."""
        self._stderr.seek(0)
        tail = self._stderr.read().decode(errors="replace").strip().splitlines()[-lines:]
        return " | ".join(t.strip() for t in tail)

    def counters(self) -> dict[str, int]:
        """Exit-summary counters, as the host apps write them: none (the image reports its counters over its
        link: MAVLink SYS_STATUS, slcan ``F``)."""
        return {}

    def stderr_bytes(self) -> dict[str, int]:
        """How much QEMU wrote to stderr (all of it kept)."""
        self._stderr.seek(0, os.SEEK_END)
        return {"total": self._stderr.tell(), "not_kept": 0}

    def _stderr_hint(self) -> str:
        text = self.stderr_tail()
        return f": {text}" if text else ""

    def stop(self, *, grace: float = 2.0) -> int | None:
        """Stop QEMU (SIGCONT if paused, SIGTERM, SIGKILL after ``grace`` s); returns its exit status."""
        proc = self.proc
        if proc is None:
            return None
        if proc.poll() is None:
            if self.paused:
                self._signal(signal.SIGCONT)
            self._signal(signal.SIGTERM)
            try:
                proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                self._signal(signal.SIGKILL)
                proc.wait(timeout=grace)
        return proc.returncode

    def close(self) -> None:
        """Stop QEMU and drop its captured stderr and a temporary flash directory."""
        self.stop()
        self._stderr.close()
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> QemuUart:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def gains_of(ready_line: str) -> dict | None:
    """The gain set a MAVLink node's start-up line (host app or image) says is in force: ``{"set": "artifact" or
    "persisted", "crc32": int, "format": "float32"...}``; ``None`` for a line that names none (an slcan node, the
    Python reference node)."""
    m = re.search(r"\bgains=(artifact|persisted) crc32=(\d+)", ready_line)
    if m is None:
        return None
    fmt = re.search(r"\bformat=(\S+)", ready_line)
    return {"set": m.group(1), "crc32": int(m.group(2)), "format": fmt.group(1) if fmt else None}


def refuse_other_wire(ready_line: str, *, what: str, stop) -> None:
    """Stop the node (``stop()``) and raise :class:`FirmwareError`, in one line, when its start-up line speaks another
    sample/command wire format than this gainlink (``wire=N``, :data:`gainlink.shipping.flags.WIRE_VERSION`; a line
    without one is a firmware from before the format was versioned): its status bits would be read at other places."""
    m = re.search(r"\bwire=(\d+)", ready_line)
    if m is None or int(m.group(1)) != WIRE_VERSION:
        stop()
        theirs = f"wire format {m.group(1)}" if m else "a wire format from before it was versioned"
        raise FirmwareError(
            f"{what} speaks {theirs}, this gainlink wire format {WIRE_VERSION}: rebuild its firmware with this gainlink"
        )


def refuse_persisted(ready_line: str, *, what: str, stop) -> None:
    """Stop the node (``stop()``) and raise :class:`FirmwareError` when its start-up line says that a persisted gain
    set runs, not its artifact's: a run compared against the artifact would be compared against other gains."""
    gains = gains_of(ready_line)
    if gains is not None and gains["set"] != "artifact":
        stop()
        raise FirmwareError(
            f"{what} {gains_in_force(ready_line)}: it would not be the artifact's gains under test (start it from "
            "the artifact)"
        )


def gains_in_force(ready_line: str) -> str:
    """:func:`gains_of` in words: ``runs the artifact's gain set (float32, crc32 0x...)`` or ``runs the gain set
    persisted by an earlier upload (...), NOT the artifact's``; ``""`` for a line that names none."""
    gains = gains_of(ready_line)
    if gains is None:
        return ""
    crc = f"{gains['format'] + ', ' if gains['format'] else ''}crc32 0x{gains['crc32']:08x}"
    if gains["set"] == "artifact":
        return f"runs the artifact's gain set ({crc})"
    return (
        f"runs the gain set persisted by an earlier upload ({crc}), NOT the artifact's (--from-artifact starts on it)"
    )


def default_flash_dir(artifact_path: Path, *, board: str) -> Path:
    """Where ``gainlink firmware run --target cortex-mN`` keeps the image's flash: beside the artifact."""
    return Path(artifact_path).with_name(f"flash-{board}")


def run_foreground(
    artifact_path: Path,
    *,
    target: str | None = None,
    board: str | None = None,
    protocol: str,
    url: str,
    options: Sequence[str] = (),
    flash_dir: Path | None = None,
) -> int:
    """Build the image for an artifact and serve ``protocol`` on its UART at ``url`` until interrupted.

    Parameters
    ----------
    artifact_path : Path
        gains.json.
    target : str, optional
        Cortex-M core (default cortex-m4; a board alone implies its core).
    board : str, optional
        QEMU machine (default: the target's first board).
    protocol : {"mavlink", "slcan"}
        What the image speaks.
    url : str
        ``tcp:HOST:PORT`` (MAVLink) or ``socket://HOST:PORT`` (slcan): where QEMU serves the UART.
    options : sequence of str
        The protocol's ``key=value`` options.
    flash_dir : Path, optional
        The image's flash (default :func:`default_flash_dir`).

    Returns
    -------
    int
        0 after SIGINT/SIGTERM, else QEMU's exit status.
    """
    from ..shipping.artifact import load
    from ..shipping.law_c import law_name
    from .build import build
    from .targets import resolve_cortex_m

    platform = resolve_cortex_m(target, board)
    board = platform.board.name
    artifact = load(artifact_path)
    refusal = platform.board.serving_refusal(protocol, law=law_name(artifact))
    if refusal is not None:
        raise FirmwareError(refusal)
    host, port = tcp_endpoint(url, scheme="tcp" if protocol == "mavlink" else "socket")
    elf = build(artifact, target=platform.target.name, board=board).files["elf"]
    flash = flash_dir or default_flash_dir(Path(artifact_path), board=board)
    stop = {"now": False}

    def on_term(signum: int, frame: object) -> None:
        stop["now"] = True

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        with QemuUart(
            elf, board=board, protocol=protocol, host=host, port=port, options=options, flash_dir=flash
        ) as image:
            runs = gains_in_force(image.ready_line)
            print(
                f"{image.ready_line}; UART at {url} (flash: {flash}){'; ' + runs if runs else ''}; Ctrl-C stops it",
                flush=True,
            )
            while not stop["now"] and image.exit_status() is None:
                time.sleep(0.2)
            code = image.exit_status()
    except KeyboardInterrupt:
        return 0
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0 if code is None else code
