"""The ``native`` engine: the host build of the C loop, driven through ctypes.

:class:`NativeLoop` owns one ``gl_loop_t`` in a ctypes buffer and exposes the C API (step, idle,
stage, reset) plus :meth:`NativeLoop.run`, which hands a whole block of samples to
``gl_loop_run_block`` in one call.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from ..firmware.build import build
from ..proof.reference import Trace
from ..shipping import gains_layout
from ..shipping.artifact import Artifact
from ..shipping.codegen import shape_of
from ..shipping.codegen_fixed import is_fixed
from . import fixed as fixed_engine

STATUS = {
    0: "GL_OK",
    1: "GL_SATURATED",
    -1: "GL_ERR_NULL",
    -2: "GL_ERR_NANINF",
    -3: "GL_ERR_CRC",
    -4: "GL_ERR_DIMS",
    -5: "GL_ERR_RANGE",
    -6: "GL_ERR_WATCHDOG",
    -7: "GL_ERR_BUSY",
    -8: "GL_ERR_FPU",
}


@dataclass(frozen=True)
class StepOutput:
    """One C step: the command, the C status code, and the saturation mask."""

    u: np.ndarray
    status: int
    sat_mask: int


class NativeLoop:
    """One ``gl_loop_t`` of the host library built for ``artifact``.

    Parameters
    ----------
    artifact : Artifact
        The artifact (the library is built for it, cached by sha256).
    watchdog_periods : int
        Idle periods before the safe command.
    library : Path, optional
        A prebuilt ``libgainlink_host.so`` for this artifact (default: build it).
    """

    def __init__(self, artifact: Artifact, *, watchdog_periods: int = 10, library: Path | None = None) -> None:
        artifact.require_unscheduled("the native engine")
        self.artifact = artifact
        path = library or build(artifact, target="host", only="gainlink_host").files["shared"]
        self.library = Path(path)
        # The per-step functions take microseconds: called through PyDLL they keep the GIL. Through CDLL
        # each call releases and retakes it, and a thread waiting for the GIL (a Dask worker's event loop)
        # is woken by every release and loses every race (a C step is shorter than a wake-up), so its
        # switch-interval timer never expires: measured in a campaign worker, 7,000 futex calls a second
        # and 3 % of a CPU in the event loop, 10 % more CPU in the run itself. The block call is long and
        # releases the GIL (CDLL).
        lib = ctypes.PyDLL(str(path))
        self._lib = lib
        self._run_block = ctypes.CDLL(str(path)).gl_loop_run_block
        lib.gl_host_artifact_sha256.restype = ctypes.c_char_p
        sha = lib.gl_host_artifact_sha256().decode()
        if sha != artifact.sha256:
            raise FirmwareError(f"library {path} was built for artifact {sha[:12]}..., not {artifact.sha256[:12]}...")
        lib.gl_host_loop_size.restype = ctypes.c_size_t
        lib.gl_host_gains_size.restype = ctypes.c_size_t
        a = artifact
        self.Gains = gains_layout.GAINS.ctypes_struct(shape_of(a))  # the build asserts the C layout equals it
        if ctypes.sizeof(self.Gains) != lib.gl_host_gains_size():
            raise FirmwareError("gl_gains_t layout of the library differs from the Python mirror")
        lib.gl_host_default_gains.restype = ctypes.POINTER(self.Gains)
        self.qa = max(a.q, 1)
        size = lib.gl_host_loop_size()
        self._loop = (ctypes.c_uint64 * ((size + 7) // 8))()
        fp = ctypes.POINTER(ctypes.c_float)
        lib.gl_loop_init.argtypes = [ctypes.c_void_p, ctypes.POINTER(self.Gains), ctypes.c_uint32]
        lib.gl_loop_stage.argtypes = [ctypes.c_void_p, ctypes.POINTER(self.Gains)]
        lib.gl_loop_step.argtypes = [ctypes.c_void_p, fp, fp, fp]
        lib.gl_loop_idle.argtypes = [ctypes.c_void_p, fp]
        lib.gl_loop_reset.argtypes = [ctypes.c_void_p]
        lib.gl_host_sat_mask.argtypes = [ctypes.c_void_p]
        lib.gl_host_sat_mask.restype = ctypes.c_uint32
        lib.gl_loop_active_crc32.argtypes = [ctypes.c_void_p]
        lib.gl_loop_active_crc32.restype = ctypes.c_uint32
        lib.gl_gains_crc32.argtypes = [ctypes.POINTER(self.Gains)]
        lib.gl_gains_crc32.restype = ctypes.c_uint32
        lib.gl_gains_check.argtypes = [ctypes.POINTER(self.Gains)]
        self._run_block.argtypes = [
            ctypes.c_void_p,
            ctypes.c_uint32,
            fp,
            fp,
            fp,
            ctypes.POINTER(ctypes.c_uint32),
            fp,
            fp,
            ctypes.POINTER(ctypes.c_uint8),
        ]
        status = lib.gl_loop_init(self._loop, lib.gl_host_default_gains(), watchdog_periods)
        if status != 0:
            raise FirmwareError(f"gl_loop_init rejected the artifact's gains: {STATUS.get(status, status)}")

    def default_gains(self) -> ctypes.Structure:
        """A writable copy of the library's built-in gain set."""
        g = self.Gains()
        ctypes.memmove(ctypes.byref(g), self._lib.gl_host_default_gains(), ctypes.sizeof(g))
        return g

    def crc32(self, gains: ctypes.Structure) -> int:
        """``gl_gains_crc32`` of ``gains``."""
        return int(self._lib.gl_gains_crc32(ctypes.byref(gains)))

    def active_crc32(self) -> int:
        """Checksum of the running gain set."""
        return int(self._lib.gl_loop_active_crc32(self._loop))

    def stage(self, gains: ctypes.Structure) -> int:
        """``gl_loop_stage``: returns the C status (0 = staged, applied at the next step)."""
        return int(self._lib.gl_loop_stage(self._loop, ctypes.byref(gains)))

    def reset(self) -> int:
        """``gl_loop_reset``."""
        return int(self._lib.gl_loop_reset(self._loop))

    def step(self, y: np.ndarray, r: np.ndarray | None = None) -> StepOutput:
        """One ``gl_loop_step`` (for tests of single samples; use :meth:`run` for blocks)."""
        a = self.artifact
        with np.errstate(over="ignore"):  # beyond float32 is inf, as on the wire: the C's fault path answers it
            yy = np.ascontiguousarray(np.asarray(y, dtype=np.float32).reshape(a.p))
            rr = np.ascontiguousarray(
                np.zeros(self.qa, np.float32) if r is None else np.asarray(r, np.float32).reshape(a.q)
            )
        u = np.zeros(a.m, dtype=np.float32)
        st = self._lib.gl_loop_step(self._loop, _fptr(yy), _fptr(rr), _fptr(u))
        return StepOutput(u=u, status=int(st), sat_mask=int(self._sat_mask()))

    def idle(self) -> StepOutput:
        """One ``gl_loop_idle`` (a period without measurement)."""
        u = np.zeros(self.artifact.m, dtype=np.float32)
        st = self._lib.gl_loop_idle(self._loop, _fptr(u))
        return StepOutput(u=u, status=int(st), sat_mask=0)

    def _sat_mask(self) -> int:
        return int(self._lib.gl_host_sat_mask(self._loop))

    def run_raw(self, Y: np.ndarray, R: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Run a block in one C call; return the float32 outputs as arrays (``u sat xh z fault``)."""
        a = self.artifact
        Y = np.ascontiguousarray(np.asarray(Y, dtype=np.float32).reshape(-1, a.p))
        N = Y.shape[0]
        if a.q > 0:
            R = np.ascontiguousarray(np.asarray(R, dtype=np.float32).reshape(N, a.q))
        else:
            R = np.zeros((N, 1), dtype=np.float32)
        U = np.zeros((N, a.m), np.float32)
        S = np.zeros(N, np.uint32)
        XH = np.zeros((N, a.n), np.float32)
        Z = np.zeros((N, self.qa), np.float32)
        F = np.zeros(N, np.uint8)
        st = self._run_block(
            self._loop,
            N,
            _fptr(Y),
            _fptr(R),
            _fptr(U),
            S.ctypes.data_as(ctypes.POINTER(ctypes.c_uint32)),
            _fptr(XH),
            _fptr(Z),
            F.ctypes.data_as(ctypes.POINTER(ctypes.c_uint8)),
        )
        if st != 0:
            raise FirmwareError(f"gl_loop_run_block failed: {STATUS.get(st, st)}")
        return {"u": U, "sat": S, "xh": XH, "z": Z[:, : a.q], "fault": F}

    def run(self, Y: np.ndarray, R: np.ndarray | None = None) -> Trace:
        """Run a block of samples from the current state; see :func:`run`."""
        return trace_from_raw(self.run_raw(Y, R), m=self.artifact.m)


def trace_from_raw(raw: dict[str, np.ndarray], *, m: int) -> Trace:
    """Turn float32 firmware outputs into a :class:`~gainlink.proof.reference.Trace` (float64 values)."""
    bits = (raw["sat"][:, None] >> np.arange(m, dtype=np.uint32)[None, :]) & 1
    return Trace(
        u=raw["u"].astype(np.float64),
        saturated=bits.astype(bool),
        xh=raw["xh"].astype(np.float64),
        z=raw["z"].astype(np.float64),
        fault=raw["fault"].astype(bool),
    )


def _fptr(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_float))


def run(artifact: Artifact, Y: np.ndarray, R: np.ndarray) -> Trace:
    """Replay ``Y`` (N, p) and ``R`` (N, q) through the host C library from the artifact's initial state.

    Parameters
    ----------
    artifact : Artifact
        The artifact (its host library is built and cached on first use).
    Y, R : ndarray
        Measurements and references, one row per step (cast to float32).

    Returns
    -------
    Trace
        The C loop's outputs (float32 values as float64 arrays); for a fixed-point artifact, the integer
        loop's (:mod:`gainlink.engines.fixed`).
    """
    if is_fixed(artifact):
        return fixed_engine.run_native(artifact, Y, R)
    return NativeLoop(artifact).run(Y, R)
