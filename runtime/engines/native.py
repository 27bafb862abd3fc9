"""The ``native`` engine: the host build of the C loop, driven through ctypes.

:class:`NativeLoop` owns the float32 law's instance (:class:`gainlink.firmware.host.HostLaw`: a ``gl_loop_t``) and
exposes its C API (step, idle, stage, reset) plus :meth:`NativeLoop.run`, which hands a whole block of samples to the
library in one call (``gl_host_law_run``).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from ..firmware.build import build
from ..firmware.host import HostLaw
from ..proof.reference import Trace
from ..shipping import gains_layout
from ..shipping.artifact import Artifact
from ..shipping.codegen import shape_of
from ..shipping.law_c import require_structure
from ..shipping.records import column


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
        require_structure(artifact, "lq", "the native engine")
        self.artifact = artifact
        path = library or build(artifact, target="host", only="gainlink_host").files["shared"]
        self.host = HostLaw(artifact, library=Path(path), watchdog_periods=watchdog_periods)
        self.library = self.host.library
        # The per-call functions take microseconds: called through PyDLL they keep the GIL. Through CDLL
        # each call releases and retakes it, and a thread waiting for the GIL (a Dask worker's event loop)
        # is woken by every release and loses every race (a C step is shorter than a wake-up), so its
        # switch-interval timer never expires: measured in a campaign worker, 7,000 futex calls a second
        # and 3 % of a CPU in the event loop, 10 % more CPU in the run itself. The block call
        # (gainlink.firmware.host) is long and releases the GIL (CDLL).
        lib = ctypes.PyDLL(str(path))
        self._lib = lib
        lib.gl_host_gains_bytes.restype = ctypes.c_size_t
        a = artifact
        self.Gains = gains_layout.GAINS.ctypes_struct(shape_of(a))  # the build asserts the C layout equals it
        if ctypes.sizeof(self.Gains) != lib.gl_host_gains_bytes():
            raise FirmwareError("gl_gains_t layout of the library differs from the Python mirror")
        lib.gl_host_default_gains.restype = ctypes.POINTER(self.Gains)
        self.qa = max(a.q, 1)
        self._loop = self.host.address  # the law's instance: a gl_loop_t (gl_law.h), the law's own functions take it
        lib.gl_loop_stage.argtypes = [ctypes.c_void_p, ctypes.POINTER(self.Gains)]
        lib.gl_loop_reset.argtypes = [ctypes.c_void_p]
        lib.gl_loop_active_crc32.argtypes = [ctypes.c_void_p]
        lib.gl_loop_active_crc32.restype = ctypes.c_uint32
        lib.gl_gains_crc32.argtypes = [ctypes.POINTER(self.Gains)]
        lib.gl_gains_crc32.restype = ctypes.c_uint32
        lib.gl_gains_check.argtypes = [ctypes.POINTER(self.Gains)]

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
        """One step (for tests of single samples; use :meth:`run` for blocks)."""
        rec = self.host.step(y, r)
        return StepOutput(u=rec["u"].copy(), status=int(rec["status"]), sat_mask=int(rec["sat"]))

    def idle(self) -> StepOutput:
        """One period without measurement (``gl_loop_idle``)."""
        rec = self.host.idle()
        return StepOutput(u=rec["u"].copy(), status=int(rec["status"]), sat_mask=0)

    def run_raw(self, Y: np.ndarray, R: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Run a block in one C call; return the float32 outputs as arrays (``u sat xh z fault``)."""
        a = self.artifact
        rec = self.host.run(Y, R if a.q else None)
        z = np.ascontiguousarray(column(rec, "z")[:, : a.q])
        return {"u": column(rec, "u"), "sat": column(rec, "sat"), "xh": column(rec, "xh"), "z": z,
                "fault": (rec["status"] == -2).astype(np.uint8)}  # fmt: skip

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
