"""The built-in plants' compiled RK4 (``native/ode.c``): built on first use with the host C compiler, loaded with
ctypes.

The library is built as every kernel of gainlink's own is (:mod:`gainlink.firmware.c_kernel`): into the firmware
build cache, in a folder named by a hash of the source, the flags and the compiler, under that folder's file lock,
through a temporary name renamed into place.

Flags keep IEEE semantics (``-O2 -ffp-contract=off``, no ``-ffast-math``): the C rounds every product and sum as
numpy does, and a row's bits do not depend on the batch size (``native/ode.c`` says how). sin and cos are SLEEF's
deterministic ``Sleef_cinz_sincosd*_u10`` (Debian's ``libsleef-dev``, linked ``-lsleef``), through the widest vector
extension this machine has (:func:`vector_flags`: AVX-512F, else AVX, else the compiler's default), which is part of
the library's key. A missing SLEEF is one ``ToolchainError`` line naming the package.
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path

import numpy as np
from gainlink.errors import ToolchainError
from gainlink.firmware.c_kernel import kernel_library

SOURCE = Path(__file__).resolve().parent / "native" / "ode.c"
LIBRARY = "libgainlink_plants.so"
SLEEF_PACKAGE = "libsleef-dev"
_MISSING_SLEEF = (f"SLEEF not found: the built-in plants' RK4 takes sin and cos from SLEEF's deterministic functions "
                  f"(install the Debian package {SLEEF_PACKAGE}; make setup does)")  # fmt: skip


def library() -> Path:
    """The kernel's shared library, built (once per source, flags and compiler) into the build cache
    (:func:`gainlink.firmware.c_kernel.kernel_library`, with this machine's :func:`vector_flags` and SLEEF); looked up
    once per process and compiler name (a lookup reads and hashes the source, finds the compiler and the cache: ~0.5
    ms)."""
    return kernel_library(SOURCE, name=LIBRARY, what="the built-in plants' RK4", flags=_vector_flags(),
                          libs=("-lsleef", "-lm"), explain=_missing_sleef)  # fmt: skip


def _missing_sleef(output: str) -> str | None:
    """The line naming SLEEF's package when the compiler's ``output`` says its header or library is missing."""
    return _MISSING_SLEEF if "sleef.h" in output or "-lsleef" in output else None


def vector_flags(cpuinfo: Path = Path("/proc/cpuinfo")) -> tuple[str, ...]:
    """The compiler flag naming the widest x86 vector extension of this machine that SLEEF's deterministic sincos
    has (``-mavx512f``, ``-mavx``; none elsewhere: SSE2 on x86-64, SLEEF's scalar build on other machines). The
    library is built on the machine that runs it; every choice gives the same bits (``native/ode.c``)."""
    try:
        text = cpuinfo.read_text()
    except OSError:
        return ()
    flags = next((line.split(":", 1)[1].split() for line in text.splitlines() if line.startswith("flags")), [])
    return ("-mavx512f",) if "avx512f" in flags else ("-mavx",) if "avx" in flags else ()


@functools.cache
def _vector_flags() -> tuple[str, ...]:
    return vector_flags()


@functools.cache
def _loaded(path: Path) -> ctypes.PyDLL:
    # PyDLL: the call keeps the GIL (a batch of one takes a microsecond; gainlink.engines.native says why that matters
    # in a Dask worker)
    try:
        return ctypes.PyDLL(str(path))
    except OSError as exc:
        if "sleef" in str(exc):  # built here, the shared SLEEF removed since
            raise ToolchainError(_MISSING_SLEEF) from None
        raise


def step_function(model: str) -> ctypes._CFuncPtr:
    """``gl_ode_<model>(rows, substeps, hh, X, U, P, failed) -> failed rows`` of the kernel (``native/ode.c``)."""
    fn = getattr(_loaded(library()), f"gl_ode_{model}")
    fn.argtypes = [ctypes.c_int64, ctypes.c_int64, ctypes.c_double] + [ctypes.c_void_p] * 4
    fn.restype = ctypes.c_int64
    return fn


class Rows:
    """Rows of one built-in model stepped by the kernel: states ``X`` (B, n), full inputs ``U`` (B, inputs) and
    parameters ``P`` (B, k), each contiguous float64 held here, their addresses taken once (no conversion or
    allocation per step). ``X`` is advanced in place; a failed row keeps its state."""

    def __init__(self, model: str, X: np.ndarray, P: np.ndarray, inputs: int) -> None:
        self.X = np.ascontiguousarray(X, dtype=np.float64)
        self.P = np.ascontiguousarray(P, dtype=np.float64)
        self.U = np.zeros((len(self.X), inputs))
        self.failed = np.zeros(len(self.X), dtype=np.bool_)
        self._fn = step_function(model)
        self._args = [ctypes.c_void_p(a.ctypes.data) for a in (self.X, self.U, self.P, self.failed)]

    @property
    def address(self) -> int:
        """The address of the model's ``gl_ode_<model>`` (a loop written in C calls it as :meth:`advance` does)."""
        return int(ctypes.cast(self._fn, ctypes.c_void_p).value or 0)

    def advance(self, substeps: int, hh: float) -> int:
        """``substeps`` RK4 steps of ``hh`` under the inputs in :attr:`U`; the number of rows that failed (marked in
        :attr:`failed`)."""
        return int(self._fn(len(self.X), substeps, hh, *self._args))
