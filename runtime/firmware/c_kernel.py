"""A C file of gainlink's own compiled on first use with the host C compiler into the build cache, loaded with ctypes
(a campaign block's kernels: :mod:`gainlink.laws.lq.native_block`, and the built-in plants' RK4,
``gainlink.hil.plants.kernel``).

The library goes into :func:`~.build.cache_root`, in a folder named by a hash of the source, the flags and the
compiler (its path, size and time), under that folder's file lock: concurrent first uses (pytest-xdist or Dask
workers) build it once, the others find it done. It is written under a temporary name and renamed into place, so no
reader ever sees half of one and a failed build leaves nothing behind. A missing compiler or a failed build is one
:class:`~gainlink.errors.ToolchainError` line.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

from ..errors import ToolchainError
from ..fileio import exclusive_lock

#: IEEE semantics: every product and sum rounded once, as Python's floats and numpy's elementwise float64 are
IEEE_FLAGS = ("-std=c11", "-O2", "-ffp-contract=off", "-fPIC", "-shared")


def compiler(name: str, *, what: str) -> str:
    """The host C compiler ``name`` as a path; ``what`` (the kernel) names what needs it in the error."""
    path = shutil.which(name)
    if path is None:
        raise ToolchainError(f"C compiler {name} not found: {what} is compiled on first use "
                             "(make setup installs gcc; set CC to another)")  # fmt: skip
    return path


def kernel_library(
    source: Path,
    *,
    name: str,
    what: str,
    flags: tuple[str, ...] = (),
    libs: tuple[str, ...] = (),
    explain: Callable[[str], str | None] | None = None,
) -> Path:
    """``source`` built (once per source, flags and compiler: ``$CC``, else ``cc``) into the build cache as the
    shared library ``name``, with the compiler ``flags`` beside :data:`IEEE_FLAGS` and the libraries ``libs``;
    ``what`` names the kernel in an error, and ``explain`` (given the compiler's whole output) may say the cause in
    its own words (a missing library's package). Looked up once per process."""
    return _library(source, name, what, flags, libs, explain, os.environ.get("CC", "cc"))


@functools.cache
def _library(
    source: Path,
    name: str,
    what: str,
    flags: tuple[str, ...],
    libs: tuple[str, ...],
    explain: Callable[[str], str | None] | None,
    cc_name: str,
) -> Path:
    from .build import cache_root  # the build code loaded when a kernel is wanted, not at import

    cc = compiler(cc_name, what=what)
    st = os.stat(cc)
    key_text = "|".join([hashlib.sha256(source.read_bytes()).hexdigest(), *IEEE_FLAGS, *flags, *libs, cc,
                         str(st.st_size), str(st.st_mtime_ns)])  # fmt: skip
    folder = cache_root() / f"{Path(name).stem}-{hashlib.sha256(key_text.encode()).hexdigest()[:16]}"
    lib = folder / name
    if lib.is_file():
        return lib
    with exclusive_lock(folder / ".lock"):
        if not lib.is_file():
            _compile([cc, *IEEE_FLAGS, *flags], source, lib, libs=libs, what=what, explain=explain)
    return lib


def _compile(
    cmd: list[str], source: Path, lib: Path, *, libs: tuple[str, ...], what: str, explain: Callable | None
) -> None:
    """Compile ``source`` into ``lib`` with the compiler and flags ``cmd`` (through a temporary name in its folder,
    removed when the build fails)."""
    staging = lib.with_name(f"{lib.name}.{os.getpid()}.tmp")
    try:
        proc = subprocess.run([*cmd, "-o", str(staging), str(source), *libs], stdin=subprocess.DEVNULL,
                              capture_output=True, text=True)  # fmt: skip
        if proc.returncode != 0:
            output = proc.stdout + proc.stderr
            said = explain(output) if explain is not None else None
            if said is not None:
                raise ToolchainError(said)
            lines = output.strip().splitlines()
            first = next((ln for ln in lines if "error" in ln.lower()), lines[-1] if lines else "")
            raise ToolchainError(f"compiling {what} ({source.name}) with {cmd[0]} failed "
                                 f"(exit {proc.returncode}): {first.strip()[:300]}")  # fmt: skip
        os.replace(staging, lib)
    finally:
        staging.unlink(missing_ok=True)


@functools.cache
def loaded(path: Path) -> ctypes.PyDLL:
    """The library at ``path``, loaded once per process. PyDLL: a call keeps the GIL (a block's call takes tens of
    microseconds; :mod:`gainlink.engines.native` says why releasing it for short calls costs a Dask worker)."""
    return ctypes.PyDLL(str(path))
