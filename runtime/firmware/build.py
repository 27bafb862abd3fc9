"""CMake driver for the firmware: export the gains, configure, build, cache by artifact sha256.

Builds live under ``<repo>/.cache/firmware/<name>-<key>/`` where the key hashes the artifact's sha256,
the target, the board and the build options, so tests and commands reuse a build of the same artifact
(CMake itself rebuilds what changed in the C sources). Everything that writes into a build folder runs
under its file lock (``<build>/.lock``), so concurrent builds of one key (pytest-xdist workers, Dask workers)
build it once and the others then find it done.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from ..artifact import Artifact
from ..codegen import render_c
from ..errors import ToolchainError
from ..fileio import exclusive_lock

log = logging.getLogger(__name__)

TARGETS = ("host", "cortex-m4")
BOARDS = ("mps2-an386", "netduinoplus2")
DEFAULT_BOARD = "mps2-an386"


def repo_root() -> Path:
    """The checkout holding ``firmware/`` (gainlink is installed editable from it)."""
    return Path(__file__).resolve().parents[2]


def firmware_dir() -> Path:
    """The firmware sources (``firmware/`` of the checkout)."""
    src = repo_root() / "firmware"
    if not (src / "CMakeLists.txt").is_file():
        raise ToolchainError(f"firmware sources not found at {src} (install gainlink editable from a checkout)")
    return src


def cache_root() -> Path:
    """Where builds are cached (``.cache/firmware`` of the checkout, ignored by git)."""
    return repo_root() / ".cache" / "firmware"


@dataclass(frozen=True)
class BuildResult:
    """Where a build is and what it produced.

    ``files`` maps a role (``shared``, ``exe``, ``elf``, ``bin``, ``hex``, ``map``) to a path.
    """

    artifact_sha256: str
    target: str
    board: str | None
    build_dir: Path
    gains_dir: Path
    files: dict[str, Path] = field(default_factory=dict)


def _which(tool: str, hint: str) -> str:
    path = shutil.which(tool)
    if path is None:
        raise ToolchainError(f"{tool} not found: {hint}")
    return path


def _write_if_changed(path: Path, text: str) -> None:
    if path.is_file() and path.read_text("utf-8") == text:
        return
    path.write_text(text, "utf-8")


def _run(cmd: list[str], *, cwd: Path, what: str) -> None:
    log.debug("running %s", " ".join(cmd))
    proc = subprocess.run(cmd, cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = (proc.stdout + proc.stderr).strip().splitlines()
        for line in lines[-15:]:
            log.error("%s", line)
        first = next((ln for ln in lines if "error" in ln.lower()), lines[-1] if lines else "")
        raise ToolchainError(f"{what} failed (exit {proc.returncode}): {first.strip()[:300]}")


def build(
    artifact: Artifact,
    *,
    target: str = "host",
    board: str | None = None,
    options: dict[str, str] | None = None,
    build_root: Path | None = None,
) -> BuildResult:
    """Build the firmware for ``artifact`` (cached).

    Parameters
    ----------
    artifact : Artifact
        The artifact whose gains are compiled in.
    target : {"host", "cortex-m4"}
        Host libraries and executable, or the Cortex-M4F image.
    board : {"mps2-an386", "netduinoplus2"}, optional
        Cortex-M board (default mps2-an386); ignored for the host.
    options : dict, optional
        Extra CMake cache entries (e.g. ``{"GL_SANITIZE": "ON"}``); part of the cache key.
    build_root : Path, optional
        Cache folder (default :func:`cache_root`).

    Returns
    -------
    BuildResult

    Raises
    ------
    ToolchainError
        A tool is missing, or configure/build failed (the compiler's last lines are in the message).
    """
    if target not in TARGETS:
        raise ToolchainError(f"unknown target {target!r} (choose from {', '.join(TARGETS)})")
    if target == "host":
        board = None
    else:
        board = board or DEFAULT_BOARD
        if board not in BOARDS:
            raise ToolchainError(f"unknown board {board!r} (choose from {', '.join(BOARDS)})")
    options = dict(sorted((options or {}).items()))
    cmake = _which("cmake", "install cmake (make setup)")
    if target == "cortex-m4":
        _which("arm-none-eabi-gcc", "install gcc-arm-none-eabi and libnewlib-arm-none-eabi (make setup)")
    src = firmware_dir()
    key_text = "|".join([artifact.sha256, target, board or "", repr(options)])
    key = hashlib.sha256(key_text.encode()).hexdigest()[:16]
    root = build_root or cache_root()
    bdir = root / f"{artifact.name}-{target}-{key}"
    gen = bdir / "gen"
    gen.mkdir(parents=True, exist_ok=True)
    with exclusive_lock(bdir / ".lock"):
        for name, text in render_c(artifact).items():
            _write_if_changed(gen / name, text)
        cm = bdir / "cmake"
        if not (cm / "CMakeCache.txt").is_file():
            cfg = [cmake, "-S", str(src), "-B", str(cm), f"-DGL_GAINS_DIR={gen}", f"-DGL_TARGET={target}"]
            if target == "host" and "GL_APPS" not in options:
                cfg.append("-DGL_APPS=OFF")  # the library, shared object and loop executable only
            if target == "cortex-m4":
                cfg += [f"-DCMAKE_TOOLCHAIN_FILE={src / 'cmake' / 'arm-none-eabi.cmake'}", f"-DGL_BOARD={board}"]
            cfg += [f"-D{k}={v}" for k, v in options.items()]
            try:
                _run(cfg, cwd=bdir, what=f"CMake configure ({target})")
            except ToolchainError:
                shutil.rmtree(cm, ignore_errors=True)
                raise
        jobs = str(min(2, os.cpu_count() or 1))
        _run([cmake, "--build", str(cm), "-j", jobs], cwd=bdir, what=f"firmware build ({target})")
    if target == "host":
        files = {
            "shared": cm / "libgainlink_host.so",
            "exe": cm / "gainlink_loop_host",
            "static": cm / "libgainlink_loop.a",
        }
    else:
        files = {ext: cm / f"gainlink_image.{ext}" for ext in ("elf", "bin", "hex", "map")}
    return BuildResult(
        artifact_sha256=artifact.sha256, target=target, board=board, build_dir=cm, gains_dir=gen, files=files
    )


def host_app(artifact: Artifact, *, target: str, relpath: str, build_root: Path | None = None) -> Path:
    """Build (cached) the host firmware with its apps and return the executable ``relpath`` of app ``target``.

    A cached build tree configured before that app existed is reconfigured and the app's target built.

    Raises
    ------
    ToolchainError
        When the build fails or does not produce the executable.
    """
    result = build(artifact, target="host", options={"GL_APPS": "ON"}, build_root=build_root)
    exe = result.build_dir / relpath
    with exclusive_lock(result.build_dir.parent / ".lock"):
        if not exe.is_file():
            _run(["cmake", str(result.build_dir)], cwd=result.build_dir, what=f"reconfiguring for {target}")
            _run(
                ["cmake", "--build", str(result.build_dir), "--target", target, "-j", "2"],
                cwd=result.build_dir,
                what=f"building {target}",
            )
    if not exe.is_file():
        raise ToolchainError(f"{target} was not built (expected {exe})")
    return exe
