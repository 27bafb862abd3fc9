"""CMake driver for the firmware: export the gains, configure, build, cache by artifact sha256.

Builds live under ``<repo>/.cache/firmware/<name>-<target>-<key>/`` where the key hashes the artifact's
sha256, the target, the board and the build options, so tests and commands reuse a build of the same
artifact and two targets or boards never share a folder (CMake itself rebuilds what changed in the C
sources; a build is not started at all while the sources and the tree's products are as the last build left them).
Everything that writes into a build folder runs under its file lock (``<build>/.lock``), so concurrent builds of one
key (pytest-xdist workers, Dask workers) build it once and the others then find it done. Targets and boards:
:mod:`gainlink.firmware.targets`.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ToolchainError
from ..fileio import exclusive_lock
from ..shipping.artifact import Artifact
from ..shipping.export_c import render_export
from . import targets as _targets

log = logging.getLogger(__name__)

TARGETS = tuple(_targets.TARGETS)  # host and every Cortex-M core
BOARDS = tuple(_targets.BOARDS)
DEFAULT_BOARD = _targets.DEFAULT_BOARD


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


def _write_if_changed(path: Path, text: str) -> bool:
    """Write ``text`` unless ``path`` holds it already; True when it wrote."""
    if path.is_file() and path.read_text("utf-8") == text:
        return False
    path.write_text(text, "utf-8")
    return True


def _build_stamp(cm: Path) -> str:
    """What a finished build was made from and made: the path, size and modification time of every firmware source
    and of every file at the top of the tree ``cm`` (its products), hashed. A millisecond, where ``cmake --build``
    of a finished tree takes a tenth of a second to find nothing to do."""
    digest = hashlib.sha256()
    for root, dirs, files in os.walk(firmware_dir()):
        dirs.sort()
        for name in sorted(files):
            st = os.stat(os.path.join(root, name))
            digest.update(f"{root}/{name} {st.st_size} {st.st_mtime_ns}\n".encode())
    for entry in sorted(os.scandir(cm), key=lambda e: e.name):
        if entry.is_file():
            st = entry.stat()
            digest.update(f"{entry.name} {st.st_size} {st.st_mtime_ns}\n".encode())
    return digest.hexdigest()


def _compiler_cache_env() -> dict[str, str]:
    """The environment of configure and build: ccache's cache in ``.cache/ccache`` of the checkout, with paths
    under the checkout hashed relative to the build folder, so builds of different artifacts share every
    translation unit that does not depend on the artifact (ignored when ccache is not installed).

    Depend mode: a miss runs the compiler alone (its ``-MD`` file lists the headers), not the preprocessor first;
    the hits across build folders are direct-mode hits either way. A cold firmware build takes ~25 % less CPU.
    """
    env = dict(os.environ)
    env.setdefault("CCACHE_DIR", str(repo_root() / ".cache" / "ccache"))
    env.setdefault("CCACHE_BASEDIR", str(repo_root()))
    env.setdefault("CCACHE_NOHASHDIR", "1")
    env.setdefault("CCACHE_DEPEND", "1")
    return env


def _run(cmd: list[str], *, cwd: Path, what: str) -> None:
    log.debug("running %s", " ".join(cmd))
    proc = subprocess.run(
        cmd, cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True, text=True, env=_compiler_cache_env()
    )
    if proc.returncode != 0:
        lines = (proc.stdout + proc.stderr).strip().splitlines()
        for line in lines[-15:]:
            log.error("%s", line)
        # the linker's own words when the image does not fit its memory, else the first error
        first = next((ln for ln in lines if "overflowed by" in ln), None)
        first = first or next((ln for ln in lines if "error" in ln.lower()), lines[-1] if lines else "")
        raise ToolchainError(f"{what} failed (exit {proc.returncode}): {first.strip()[:300]}")


def build(
    artifact: Artifact,
    *,
    target: str = "host",
    board: str | None = None,
    options: dict[str, str] | None = None,
    build_root: Path | None = None,
    only: str | None = None,
) -> BuildResult:
    """Build the firmware for ``artifact`` (cached).

    Parameters
    ----------
    artifact : Artifact
        The artifact whose gains are compiled in.
    target : {"host", "cortex-m0", "cortex-m3", "cortex-m4", "cortex-m7", "cortex-m33", "cortex-m55"}
        Host libraries and executable, or the image for that Cortex-M core.
    board : str, optional
        QEMU board of a Cortex-M image (default: the target's first, e.g. mps2-an386 for cortex-m4; see
        :mod:`gainlink.firmware.targets`); must be None for the host.
    options : dict, optional
        Extra CMake cache entries (e.g. ``{"GL_SANITIZE": "ON"}``); part of the cache key.
    build_root : Path, optional
        Cache folder (default :func:`cache_root`).
    only : str, optional
        Build only this CMake target of the tree (e.g. one host app), not all of them.

    Returns
    -------
    BuildResult

    Raises
    ------
    ToolchainError
        An unknown target or board, a board without that core, a missing tool, or a failed configure or
        build (the compiler's last lines are in the message).
    """
    platform = _targets.resolve(target, board, default_target=_targets.HOST)
    options = dict(sorted((host_options(platform) | (options or {})).items()))
    cmake = _which("cmake", "install cmake (make setup)")
    if platform.board is not None:
        _which("arm-none-eabi-gcc", "install gcc-arm-none-eabi and libnewlib-arm-none-eabi (make setup)")
    board = platform.board.name if platform.board else None
    key_text = "|".join([artifact.sha256, target, board or "", repr(options)])
    key = hashlib.sha256(key_text.encode()).hexdigest()[:16]
    bdir = (build_root or cache_root()) / f"{artifact.name}-{target}-{key}"
    gen = bdir / "gen"
    cm = bdir / "cmake"
    gen.mkdir(parents=True, exist_ok=True)
    cm = bdir / "cmake"
    with exclusive_lock(bdir / ".lock"):
        written = [_write_if_changed(gen / name, text) for name, text in render_export(artifact).items()]
        if not (cm / "CMakeCache.txt").is_file():
            _configure(cmake, cm, gen=gen, platform=platform, options=options)
        # A build of this target is not run again while the sources, the export and the tree's products are as
        # the last one left them.
        done = bdir / f".built-{only or 'all'}"
        if any(written) or not done.is_file() or done.read_text() != _build_stamp(cm):
            done.unlink(missing_ok=True)
            what = f"firmware build ({target}{', ' + only if only else ''})"
            _run(_build_command(cmake, cm, only), cwd=bdir, what=what)
            done.write_text(_build_stamp(cm))
    return BuildResult(
        artifact_sha256=artifact.sha256,
        target=target,
        board=board,
        build_dir=cm,
        gains_dir=gen,
        files=_outputs(cm, platform),
    )


def host_options(platform: _targets.Platform) -> dict[str, str]:
    """The CMake options a host build takes from the machine it runs on: ``GL_HOST_FMA=ON`` on an x86-64 CPU with
    FMA (:func:`host_has_fma`), so the law's fused multiply-adds are instructions, not libm calls (the same bits);
    none for a Cortex-M image or elsewhere. Part of the build's key, as every option."""
    if platform.board is None and host_has_fma():
        return {"GL_HOST_FMA": "ON"}
    return {}


@functools.lru_cache(maxsize=1)
def host_has_fma() -> bool:
    """Whether this is Linux on an x86-64 CPU with the FMA instructions (``fma`` among ``/proc/cpuinfo``'s flags).
    An aarch64 compiler inlines ``fmaf`` without a flag; elsewhere the host keeps libm's call."""
    import platform as _platform

    if sys.platform != "linux" or _platform.machine() != "x86_64":
        return False
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return "fma" in line.split(":", 1)[1].split()
    except OSError:
        return False
    return False


def _build_command(cmake: str, cm: Path, only: str | None) -> list[str]:
    """The command that builds the tree ``cm`` (all of it, or the CMake target ``only``): Ninja itself when the tree
    is Ninja's (it reruns CMake when a CMakeLists changed, as ``cmake --build`` would, without a CMake process in
    front of every build), else ``cmake --build``."""
    jobs = str(min(2, os.cpu_count() or 1))
    ninja = shutil.which("ninja")
    if ninja is not None and (cm / "build.ninja").is_file():
        return [ninja, "-C", str(cm), "-j", jobs, *([only] if only else [])]
    return [cmake, "--build", str(cm), "-j", jobs, *(["--target", only] if only else [])]


def _configure(cmake: str, cm: Path, *, gen: Path, platform: _targets.Platform, options: dict[str, str]) -> None:
    """Configure the CMake tree ``cm`` for ``platform`` (removed again when configuring fails)."""
    src = firmware_dir()
    target = platform.target.name
    cfg = [cmake, "-S", str(src), "-B", str(cm), f"-DGL_GAINS_DIR={gen}", f"-DGL_TARGET={target}"]
    if shutil.which("ninja") is not None:  # Ninja and ccache are installed by `make setup`: faster, same output
        cfg.append("-GNinja")
    if shutil.which("ccache") is not None:
        cfg.append("-DCMAKE_C_COMPILER_LAUNCHER=ccache")
    if _uses_mavlink(platform, options):
        cfg.append(f"-DGL_MAVLINK_HEADERS={mavlink_headers()}")
    if platform.board is None and "GL_APPS" not in options:
        cfg.append("-DGL_APPS=OFF")  # the library, shared object and loop executable only
    if platform.board is not None:
        cfg += [
            f"-DCMAKE_TOOLCHAIN_FILE={src / 'cmake' / 'arm-none-eabi.cmake'}",
            f"-DGL_BOARD={platform.board.name}",
        ]
    cfg += [f"-D{k}={v}" for k, v in options.items()]
    seed = _platform_seed(cmake, platform, options)
    seeded = _plant_seed(seed, cm)
    try:
        _run(
            cfg + (["-DCMAKE_PLATFORM_INFO_INITIALIZED=1"] if seeded else []),
            cwd=cm.parent,
            what=f"CMake configure ({platform.name})",
        )
    except ToolchainError:
        shutil.rmtree(cm, ignore_errors=True)
        if not seeded:
            raise
        shutil.rmtree(seed, ignore_errors=True)  # a kept detection this CMake no longer takes: detect anew
        _configure(cmake, cm, gen=gen, platform=platform, options=options)
        return
    if not seeded:
        _keep_seed(cm, seed)


def _platform_seed(cmake: str, platform: _targets.Platform, options: dict[str, str]) -> Path:
    """Where CMake's compiler detection for this configuration is kept: it is the same for every tree of one
    target, board and set of options (the compiler, its ABI and implicit libraries), and takes four fifths of a
    configure (0.25 of 0.3 CPU-s). The key names the CMake and compiler binaries by path, size and time, so an
    upgraded toolchain is detected anew."""
    compilers = ["arm-none-eabi-gcc" if platform.board else os.environ.get("CC", "cc"), options.get("CMAKE_C_COMPILER")]
    tools = [cmake] + [shutil.which(c) for c in compilers if c]  # an unknown compiler fails the configure itself
    stats = [f"{tool} {os.stat(tool).st_size} {os.stat(tool).st_mtime_ns}" for tool in tools if tool]
    toolchain = (firmware_dir() / "cmake" / "arm-none-eabi.cmake").read_bytes() if platform.board else b""
    text = "|".join([platform.name, repr(sorted(options.items())), *stats]) + hashlib.sha256(toolchain).hexdigest()
    return seed_root() / hashlib.sha256(text.encode()).hexdigest()[:16]


def seed_root() -> Path:
    """Where the compiler detections are kept (``.cache/cmake-platform`` of the checkout)."""
    return repo_root() / ".cache" / "cmake-platform"


def _plant_seed(seed: Path, cm: Path) -> bool:
    """Copy a kept detection into the new tree ``cm`` (``CMakeFiles/<cmake version>/``); False when none is kept."""
    versions = [d for d in seed.iterdir() if d.is_dir()] if seed.is_dir() else []
    if len(versions) != 1:
        return False
    shutil.copytree(versions[0], cm / "CMakeFiles" / versions[0].name, dirs_exist_ok=True)
    return True


def _keep_seed(cm: Path, seed: Path) -> None:
    """Keep the detection of the tree ``cm`` just configured (its platform files, without the compiler-id
    scratch) for the next tree of this configuration; published whole by a rename, first one wins."""
    found = [d for d in (cm / "CMakeFiles").iterdir() if d.is_dir() and (d / "CMakeSystem.cmake").is_file()]
    if len(found) != 1 or seed.exists():
        return
    staging = seed.with_name(f"{seed.name}.{os.getpid()}.tmp")
    shutil.rmtree(staging, ignore_errors=True)
    shutil.copytree(found[0], staging / found[0].name, ignore=shutil.ignore_patterns("CompilerId*"))
    try:
        os.rename(staging, seed)
    except OSError:  # another process kept the same detection first
        shutil.rmtree(staging, ignore_errors=True)


def _uses_mavlink(platform: _targets.Platform, options: dict[str, str]) -> bool:
    """Whether the configuration builds the MAVLink node (the host apps, a serving image, the fuzz harnesses)."""
    if options.get("GL_FUZZ") == "ON":
        return True
    if platform.board is None:
        return options.get("GL_APPS") == "ON"
    return options.get("GL_IMAGE_SERVE", "ON") == "ON"


def mavlink_headers() -> Path:
    """mavgen's MAVLink 2 C headers for the common.xml of the installed pymavlink (cached, generated once per
    pymavlink version and shared by every build: generating them is most of a host app build's time)."""
    import pymavlink

    xml = Path(pymavlink.__file__).parent / "dialects" / "v20" / "common.xml"
    key = hashlib.sha256(xml.read_bytes()).hexdigest()[:16]
    root = repo_root() / ".cache" / "mavlink-c" / f"{pymavlink.__version__}-{key}"
    if (root / "common" / "mavlink.h").is_file():
        return root
    with exclusive_lock(root.parent / ".lock"):
        if not (root / "common" / "mavlink.h").is_file():
            staging = root.with_name(root.name + ".tmp")
            shutil.rmtree(staging, ignore_errors=True)
            cmd = [sys.executable, "-m", "pymavlink.tools.mavgen", "--lang=C", "--wire-protocol=2.0"]
            _run([*cmd, f"--output={staging}", str(xml)], cwd=root.parent, what="mavgen (MAVLink C headers)")
            os.replace(staging, root)
    return root


def _outputs(cm: Path, platform: _targets.Platform) -> dict[str, Path]:
    """What a build in ``cm`` produced, by role."""
    if platform.board is None:
        return {
            "shared": cm / "libgainlink_host.so",
            "exe": cm / "gainlink_loop_host",
            "static": cm / "libgainlink_loop.a",
        }
    return {ext: cm / f"gainlink_image.{ext}" for ext in ("elf", "bin", "hex", "map")}


def replay_image(artifact: Artifact, *, target: str, board: str) -> Path:
    """The Cortex-M image that replays recorded samples and runs PIL over semihosting, without the bus nodes on
    its UART (``GL_IMAGE_SERVE=OFF``: the same loop, built in a third of the time); returns the ELF (cached)."""
    return build(artifact, target=target, board=board, options={"GL_IMAGE_SERVE": "OFF"}).files["elf"]


def host_app(artifact: Artifact, *, target: str, relpath: str, build_root: Path | None = None) -> Path:
    """Build (cached) app ``target`` of the host firmware (its tree configured with the apps; only that app is
    built) and return its executable ``relpath``.

    A cached build tree configured before that app existed is reconfigured and the app's target built.

    Raises
    ------
    ToolchainError
        When the build fails or does not produce the executable.
    """
    result = build(artifact, target="host", options={"GL_APPS": "ON"}, build_root=build_root, only=target)
    exe = result.build_dir / relpath
    with exclusive_lock(result.build_dir.parent / ".lock"):
        if not exe.is_file():
            _run(["cmake", str(result.build_dir)], cwd=result.build_dir, what=f"reconfiguring for {target}")
            _run(_build_command("cmake", result.build_dir, target), cwd=result.build_dir, what=f"building {target}")
    if not exe.is_file():
        raise ToolchainError(f"{target} was not built (expected {exe})")
    return exe
