"""Build and run the firmware's MAVLink host app (``firmware/apps/mavlink``, executable ``gainlink_mavlink``)."""

from __future__ import annotations

import logging
import os
import selectors
import signal
import subprocess
import time
from pathlib import Path

from ..errors import FirmwareError
from ..shipping.artifact import Artifact
from .capture import StderrCapture
from .foreground import run_in_foreground

log = logging.getLogger(__name__)

EXECUTABLE = "gainlink_mavlink"


def mavlink_executable(artifact: Artifact, *, build_root: Path | None = None) -> Path:
    """Build (cached) the host firmware for ``artifact`` and return its ``gainlink_mavlink`` executable.

    Raises
    ------
    ToolchainError
        When the build fails or does not produce the app.
    """
    from .build import host_app

    return host_app(artifact, target=EXECUTABLE, relpath=EXECUTABLE, build_root=build_root)


def spin_argv(busy_poll_us: int) -> list[str]:
    """The app's busy-poll option for a transport's ``busy_poll_us`` (nothing when 0: block at once)."""
    return ["--spin-us", str(int(busy_poll_us))] if busy_poll_us > 0 else []


def signing_argv(signing_key: Path | None) -> list[str]:
    """The app's signing option for a key file (nothing without one); the file is checked here first."""
    if signing_key is None:
        return []
    from ..mavlink.signing import read_key

    read_key(signing_key)  # one clear line now rather than the app's exit status later
    return ["--signing-key", str(signing_key)]


def firmware_argv(
    exe: Path,
    *,
    url: str,
    storage: Path | None = None,
    sysid: int = 1,
    compid: int = 1,
    busy_poll_us: int = 0,
    signing_key: Path | None = None,
    from_artifact: bool = False,
) -> list[str]:
    """Command line of the MAVLink app (``busy_poll_us`` > 0 adds ``--spin-us``, a key file ``--signing-key``,
    ``from_artifact`` with a ``storage`` file ``--from-artifact``: start on the artifact's set, not the stored one)."""
    argv = [str(exe), "--url", url, "--sysid", str(sysid), "--compid", str(compid), *spin_argv(busy_poll_us)]
    if storage is not None:
        argv += ["--storage", str(storage)] + (["--from-artifact"] if from_artifact else [])
    return argv + signing_argv(signing_key)


class MavlinkFirmware:
    """The MAVLink firmware app as a child process (a context manager).

    Parameters
    ----------
    exe : Path
        The ``gainlink_mavlink`` executable (:func:`mavlink_executable`).
    url : str
        Its link, e.g. ``udpin:127.0.0.1:14550``.
    storage : Path, optional
        Parameter file it persists to and loads at start.
    ready_timeout : float
        Seconds to wait for its ready line.
    busy_poll_us : int
        Poll without sleeping this long after each datagram before blocking again (``--spin-us``;
        0, the default: block at once).
    signing_key : Path, optional
        MAVLink 2 signing key file (``--signing-key``).
    from_artifact : bool
        Start on the artifact's gain set even when ``storage`` holds a persisted one (``--from-artifact``).

    Attributes
    ----------
    ready_line : str
        The app's start-up line; its ``gains=artifact|persisted crc32=... format=...`` name the set in force.
    """

    def __init__(
        self,
        exe: Path,
        *,
        url: str,
        storage: Path | None = None,
        ready_timeout: float = 10.0,
        busy_poll_us: int = 0,
        signing_key: Path | None = None,
        from_artifact: bool = False,
    ):
        self.argv = firmware_argv(
            exe,
            url=url,
            storage=storage,
            busy_poll_us=busy_poll_us,
            signing_key=signing_key,
            from_artifact=from_artifact,
        )
        self.ready_timeout = ready_timeout
        self.proc: subprocess.Popen | None = None
        self.ready_line = ""
        self._stderr: StderrCapture | None = None

    def start(self) -> MavlinkFirmware:
        """Start it and wait for ``gainlink-mavlink ...`` on its stdout."""
        try:
            self.proc = subprocess.Popen(
                self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE
            )
        except OSError as exc:
            raise FirmwareError(f"cannot start {self.argv[0]}: {exc.strerror}") from None
        self._stderr = StderrCapture(self.proc.stderr)
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        buf = b""
        deadline = time.monotonic() + self.ready_timeout
        try:
            while b"\n" not in buf:
                left = deadline - time.monotonic()
                if left <= 0:
                    self.stop()
                    raise FirmwareError(
                        f"{EXECUTABLE} sent no ready line within {self.ready_timeout:g} s: {self.stderr_text()}"
                    )
                if sel.select(timeout=left):
                    chunk = os.read(self.proc.stdout.fileno(), 4096)
                    if not chunk:
                        code = self.proc.wait(timeout=5)
                        self._stderr.join()
                        raise FirmwareError(f"{EXECUTABLE} exited with status {code}: {self.stderr_text()}")
                    buf += chunk
        finally:
            sel.close()
        self.ready_line = buf.split(b"\n", 1)[0].decode(errors="replace")
        return self

    def stderr_text(self) -> str:
        """What the app wrote to stderr so far (its first 8 KiB and last 56 KiB: the capture is bounded)."""
        return "" if self._stderr is None else self._stderr.text()

    def counters(self) -> dict[str, int]:
        """The ``key=value`` counters of the app's exit summary (after :meth:`stop`)."""
        return {} if self._stderr is None else self._stderr.counters()

    def stop(self, *, grace: float = 2.0) -> int | None:
        """SIGTERM, then SIGKILL after ``grace`` seconds; returns the exit status."""
        proc = self.proc
        if proc is None:
            return None
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=grace)
        if proc.stdout is not None:
            proc.stdout.close()
        if self._stderr is not None:
            self._stderr.join()
        return proc.returncode

    def __enter__(self) -> MavlinkFirmware:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def default_param_file(artifact_path: Path) -> Path:
    """Where ``gainlink firmware run --mavlink`` keeps persisted parameters by default: beside the artifact."""
    return Path(artifact_path).with_name("mavlink_params.txt")


def run_foreground(
    artifact_path: Path,
    *,
    url: str,
    param_file: Path | None = None,
    signing_key: Path | None = None,
    from_artifact: bool = False,
) -> int:
    """Build the MAVLink app for an artifact and run it in the foreground until interrupted.

    Parameters
    ----------
    artifact_path : Path
        gains.json.
    url : str
        The app's link (``udpin:HOST:PORT`` or ``udpout:HOST:PORT``).
    param_file : Path, optional
        Persistent parameter file (default :func:`default_param_file`); loaded at start when present.
    signing_key : Path, optional
        MAVLink 2 signing key file.
    from_artifact : bool
        Start on the artifact's gain set even when ``param_file`` holds a persisted one (kept until the next
        persist). Either way the app's start-up line names the set in force (``gains=artifact|persisted``).

    Returns
    -------
    int
        The app's exit status (0 after SIGINT/SIGTERM).
    """
    from ..shipping.artifact import load

    if not (url.startswith("udpin:") or url.startswith("udpout:")) or url.count(":") != 2:
        raise FirmwareError(f"--mavlink takes udpin:HOST:PORT or udpout:HOST:PORT, not {url!r}")
    artifact = load(artifact_path)
    signing_argv(signing_key)  # a bad key file is one line before the build, not after
    exe = mavlink_executable(artifact)
    argv = firmware_argv(
        exe,
        url=url,
        storage=param_file or default_param_file(Path(artifact_path)),
        signing_key=signing_key,
        from_artifact=from_artifact,
    )
    log.info("running %s", " ".join(argv))
    return run_in_foreground(argv, stdin=subprocess.DEVNULL)
