"""The host build's fixed-point loop stepped one sample at a time (software in the loop of a fixed-point artifact):
the integer law the artifact certifies, with the step interface of :class:`~gainlink.engines.native.NativeLoop`."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from ..firmware import fixed as fwfixed
from ..shipping.artifact import Artifact
from .native import StepOutput


class FixedNativeLoop:
    """One ``gl_fixed_loop_t`` of the host fixed-point library built for ``artifact`` (``numeric = "q31"|"q15"``).

    Parameters
    ----------
    artifact : Artifact
        A fixed-point artifact (its library is built and cached on first use).
    library : Path, optional
        A ``libgainlink_fixed_host.so`` already built for it.
    """

    def __init__(self, artifact: Artifact, *, library: Path | None = None) -> None:
        fwfixed.require_fixed(artifact)
        self.a = artifact
        self.library = Path(library or fwfixed.host_library(artifact))
        lib = self._lib = ctypes.CDLL(str(self.library))
        self.dtype = fwfixed.record_dtype(artifact)
        lib.gl_fixed_host_record_words.restype = ctypes.c_uint32
        lib.gl_fixed_host_loop_bytes.restype = ctypes.c_uint32
        if lib.gl_fixed_host_record_words() * 4 != self.dtype.itemsize:
            raise FirmwareError(f"{self.library} was not built for this artifact's dimensions")
        lib.gl_fixed_host_step.restype = ctypes.c_uint32
        lib.gl_fixed_host_step.argtypes = [ctypes.c_void_p] * 4
        self._loop = ctypes.create_string_buffer(lib.gl_fixed_host_loop_bytes())
        if lib.gl_fixed_host_init(self._loop) != 0:
            raise FirmwareError("gl_fixed_init rejected the artifact's fixed-point gains")
        self._rec = np.zeros(1, dtype=self.dtype)
        self._y = np.zeros(artifact.p, dtype=np.float32)
        self._r = np.zeros(max(artifact.q, 1), dtype=np.float32)

    @property
    def last_record(self) -> np.void:
        """The C's output record of the last step (``gainlink.firmware.fixed.record_dtype``: flags, words, ...)."""
        return self._rec[0]

    @property
    def law(self) -> str:
        """``q31`` or ``q15``."""
        return str(self.a.checks["fixed_point"]["numeric"])

    def step(self, y: np.ndarray, r: np.ndarray | None = None) -> StepOutput:
        """One step on sample ``y`` and references ``r``: the float command, the float loop's status code for it
        (:func:`gainlink.firmware.fixed.step_status`) and the saturation mask."""
        self._y[:] = np.asarray(y, dtype=np.float32).reshape(self.a.p)
        if self.a.q:
            self._r[:] = np.asarray(r, dtype=np.float32).reshape(self.a.q)
        flags = self._lib.gl_fixed_host_step(
            self._loop, self._y.ctypes.data, self._r.ctypes.data, self._rec.ctypes.data
        )
        rec = self._rec[0]
        sat = int(rec["sat"])
        return StepOutput(u=rec["u"].astype(np.float64), status=fwfixed.step_status(int(flags), sat), sat_mask=sat)
