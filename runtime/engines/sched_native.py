"""The host build of the scheduled C loop (``firmware/src/gl_sched.c``), driven through ctypes.

:class:`NativeScheduledLoop` owns one ``gl_sched_t`` in a ctypes buffer; :meth:`NativeScheduledLoop.run` hands a
block of samples to ``gl_sched_run_block`` in one call and returns a
:class:`~gainlink.proof.scheduled_reference.ScheduledTrace` (float32 values as float64 arrays).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from ..firmware.build import build
from ..proof.scheduled_reference import ScheduledTrace
from ..shipping.artifact import Artifact
from .native import STATUS

_FP = ctypes.POINTER(ctypes.c_float)
_U32P = ctypes.POINTER(ctypes.c_uint32)


def state_length(a: Artifact) -> int:
    """``GL_SCHED_STATE_LEN``: delta, u_prev, y_prev, e_prev, sigma, sigma_f, started."""
    return a.n + a.m + a.p + a.q + 3


class NativeScheduledLoop:
    """One ``gl_sched_t`` of the host library built for the scheduled ``artifact``.

    Parameters
    ----------
    artifact : Artifact
        A scheduled artifact (the library is built for it, cached by sha256).
    library : Path, optional
        A prebuilt ``libgainlink_host.so`` for this artifact (default: build it).
    """

    def __init__(self, artifact: Artifact, *, library: Path | None = None) -> None:
        if artifact.schedule is None:
            raise FirmwareError(f"artifact {artifact.name} is not scheduled: use gainlink.engines.native")
        self.artifact = artifact
        self.e = len(artifact.schedule.external)
        path = Path(library or build(artifact, target="host", only="gainlink_host").files["shared"])
        self.library = path
        lib = ctypes.PyDLL(str(path))  # short calls keep the GIL (see gainlink.engines.native)
        self._lib = lib
        lib.gl_host_artifact_sha256.restype = ctypes.c_char_p
        sha = lib.gl_host_artifact_sha256().decode()
        if sha != artifact.sha256:
            raise FirmwareError(f"library {path} was built for artifact {sha[:12]}..., not {artifact.sha256[:12]}...")
        lib.gl_host_sched_size.restype = ctypes.c_size_t
        lib.gl_host_sched_default.restype = ctypes.c_void_p
        self._loop = (ctypes.c_uint64 * ((lib.gl_host_sched_size() + 7) // 8))()
        lib.gl_sched_init.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.gl_sched_reset.argtypes = [ctypes.c_void_p]
        lib.gl_sched_step.argtypes = [ctypes.c_void_p, _FP, _FP, _FP, _FP]
        lib.gl_sched_state.argtypes = [ctypes.c_void_p, _FP]
        self._run_block = ctypes.CDLL(str(path)).gl_sched_run_block
        self._run_block.argtypes = [ctypes.c_void_p, ctypes.c_uint32, _FP, _FP, _FP, _FP, _U32P, _U32P, _FP,
                                    ctypes.POINTER(ctypes.c_int32)]  # fmt: skip
        status = lib.gl_sched_init(self._loop, lib.gl_host_sched_default())
        if status != 0:
            raise FirmwareError(f"gl_sched_init rejected the artifact's tables: {STATUS.get(status, status)}")

    def reset(self) -> int:
        """``gl_sched_reset``."""
        return int(self._lib.gl_sched_reset(self._loop))

    def state(self) -> np.ndarray:
        """``gl_sched_state``: the loop's state vector (float32)."""
        out = np.zeros(state_length(self.artifact), np.float32)
        self._lib.gl_sched_state(self._loop, out.ctypes.data_as(_FP))
        return out

    def run_raw(self, Y, R=None, S=None) -> dict[str, np.ndarray]:
        """Run a block in one C call; float32 outputs ``u sat sflags state status``."""
        a = self.artifact
        with np.errstate(over="ignore"):
            Y = np.ascontiguousarray(np.asarray(Y, dtype=np.float32).reshape(-1, a.p))
            N = Y.shape[0]
            R = np.ascontiguousarray(np.zeros((N, a.q)) if R is None else np.asarray(R).reshape(N, a.q), np.float32)
            Sx = np.zeros((N, max(self.e, 1))) if S is None or self.e == 0 else np.asarray(S).reshape(N, self.e)
            Sx = np.ascontiguousarray(Sx, dtype=np.float32)
        out = {"u": np.zeros((N, a.m), np.float32), "sat": np.zeros(N, np.uint32), "sflags": np.zeros(N, np.uint32),
               "state": np.zeros((N, state_length(a)), np.float32), "status": np.zeros(N, np.int32)}  # fmt: skip
        st = self._run_block(self._loop, N, Y.ctypes.data_as(_FP), R.ctypes.data_as(_FP), Sx.ctypes.data_as(_FP),
                             out["u"].ctypes.data_as(_FP), out["sat"].ctypes.data_as(_U32P),
                             out["sflags"].ctypes.data_as(_U32P), out["state"].ctypes.data_as(_FP),
                             out["status"].ctypes.data_as(ctypes.POINTER(ctypes.c_int32)))  # fmt: skip
        if st != 0:
            raise FirmwareError(f"gl_sched_run_block failed: {STATUS.get(st, st)}")
        return out

    def run(self, Y, R=None, S=None) -> ScheduledTrace:
        """Run a block of samples from the current state; the C's trace."""
        return scheduled_trace_from_raw(self.run_raw(Y, R, S), a=self.artifact)


def scheduled_trace_from_raw(raw: dict[str, np.ndarray], *, a: Artifact) -> ScheduledTrace:
    """Float32 outputs of a scheduled C loop (``u sat sflags state status``) as a ScheduledTrace."""
    bits = (raw["sat"][:, None] >> np.arange(a.m, dtype=np.uint32)[None, :]) & 1
    state = raw["state"].astype(np.float64)
    return ScheduledTrace(
        u=raw["u"].astype(np.float64),
        saturated=bits.astype(bool),
        fault=raw["status"] == -2,
        sigma=state[:, a.n + a.m + a.p + a.q],
        sigma_flags=raw["sflags"].astype(int),
        state=state,
    )


def run(artifact: Artifact, Y: np.ndarray, R: np.ndarray | None, S: np.ndarray | None = None) -> ScheduledTrace:
    """Replay ``Y`` (N, p), ``R`` (N, q) and the external signals ``S`` (N, e) through the host build of the
    scheduled C loop from its reset state."""
    return NativeScheduledLoop(artifact).run(Y, R, S)
