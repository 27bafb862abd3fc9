"""Build the project's plant FMUs from their C sources with fmpy, cached by content, and validate them.

``hil/fmus/<name>/`` holds ``modelDescription.xml`` and ``sources/``; the shared FMI glue in
``hil/fmus/common/`` is copied next to the sources. fmpy's CMake build does not link libm, so the
build passes ``-lm`` and ``--no-undefined`` explicitly (FIELD-NOTES).
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from gainlink.errors import PlantError, ToolchainError
from gainlink.fileio import exclusive_lock

from ..paths import cache_dir, fmu_source_dir, fmu_source_names

log = logging.getLogger(__name__)

CMAKE_OPTIONS = {
    "CMAKE_C_STANDARD_LIBRARIES:STRING": "-lm",
    "CMAKE_SHARED_LINKER_FLAGS:STRING": "-Wl,--no-undefined",
}


def _tree_files(name: str) -> list[tuple[str, Path]]:
    src = fmu_source_dir(name)
    files = [("modelDescription.xml", src / "modelDescription.xml")]
    files += sorted(
        (f"sources/{p.relative_to(src / 'sources')}", p) for p in (src / "sources").rglob("*") if p.is_file()
    )
    common = src.parent / "common"
    files += sorted((f"sources/{p.name}", p) for p in common.glob("*") if p.is_file())
    return files


@contextlib.contextmanager
def _quiet(log_path: Path):
    """Send this process's stdout/stderr file descriptors (cmake's output) to ``log_path`` meanwhile."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(log_path, "wb") as fh:
        os.dup2(fh.fileno(), 1)
        os.dup2(fh.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def source_digest(name: str) -> str:
    """sha256 over the FMU's source files (names and bytes) and the fmpy version."""
    import fmpy

    h = hashlib.sha256(f"fmpy {fmpy.__version__}\n".encode())
    for arc, path in _tree_files(name):
        h.update(arc.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def validate(path: str | os.PathLike) -> None:
    """Run fmpy's validation on an FMU; raise :class:`PlantError` listing the first problems."""
    from fmpy.validation import validate_fmu

    problems = validate_fmu(str(path))
    if problems:
        raise PlantError(f"FMU {path} fails validation: {'; '.join(problems[:3])}")


def build_fmu(name: str, *, out_dir: str | os.PathLike | None = None, force: bool = False) -> Path:
    """Build (or reuse from cache) the project FMU ``name`` and return the path of the ``.fmu``.

    Parameters
    ----------
    name : str
        One of :func:`gainlink.hil.paths.fmu_source_names`.
    out_dir : path, optional
        Where to put the ``.fmu``; default ``.cache/fmus`` of the checkout.
    force : bool
        Rebuild even when a cached FMU for the same sources exists.
    """
    if name not in fmu_source_names():
        raise PlantError(f"no project FMU named {name!r} (available: {', '.join(fmu_source_names())})")
    digest = source_digest(name)[:16]
    out = Path(out_dir) if out_dir is not None else cache_dir("fmus")
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{name}-{digest}.fmu"
    if target.is_file() and not force:
        return target
    if shutil.which("cmake") is None:
        raise ToolchainError("cmake is needed to build the plant FMUs (apt-get install cmake)")
    with exclusive_lock(out / f".{target.name}.lock"):  # one build per FMU; the others wait and reuse it
        if target.is_file() and not force:
            return target
        _build_into(name, target)
    return target


def _build_into(name: str, target: Path) -> None:
    """Build FMU ``name`` in a temporary folder, validate it and move it to ``target`` (atomically)."""
    from fmpy.build import build_platform_binary

    with tempfile.TemporaryDirectory(prefix=f"gainlink-fmu-{name}-") as tmp:
        unzip = Path(tmp) / "fmu"
        build = Path(tmp) / "build"
        build.mkdir()
        for arc, path in _tree_files(name):
            dest = unzip / arc
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, dest)
        log.info("building FMU %s with fmpy (cmake)", name)
        log_path = Path(tmp) / "build.log"
        try:
            with _quiet(log_path):
                build_platform_binary(unzip, build_dir=build, cmake_options=dict(CMAKE_OPTIONS))
        except subprocess.CalledProcessError as exc:
            tail = " | ".join(log_path.read_text(errors="replace").strip().splitlines()[-5:])
            raise ToolchainError(f"building FMU {name} failed ({exc.returncode}): {tail}") from None
        staged = Path(tmp) / f"{name}.fmu"
        with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(unzip.rglob("*")):
                if path.is_file():
                    info = zipfile.ZipInfo(path.relative_to(unzip).as_posix(), date_time=(1980, 1, 1, 0, 0, 0))
                    info.external_attr = 0o644 << 16
                    info.compress_type = zipfile.ZIP_DEFLATED
                    zf.writestr(info, path.read_bytes())
        validate(staged)
        tmp_target = target.with_suffix(f".{os.getpid()}.tmp")
        shutil.copyfile(staged, tmp_target)
        os.replace(tmp_target, target)
