"""The host build of any law, driven through ctypes: ``libgainlink_host.so`` (``firmware/ports/host/gl_host.c``).

One binding for every law (``firmware/include/gainlink/gl_law.h``): the law's instance in a ctypes buffer, a step,
an idle period or a reset answered with the law's record (:func:`gainlink.shipping.records.layout`: the numpy
dtype of the C's ``gl_law_record_t``, generated from the same description), and a block of samples in one call.
"""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FirmwareError
from ..shipping import records
from .build import build

_VP = ctypes.c_void_p
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


def library(artifact: Any) -> Path:
    """The host library of ``artifact`` (built and cached by sha256)."""
    return Path(build(artifact, target="host", only="gainlink_host").files["shared"])


class HostLaw:
    """One instance of the law ``artifact`` runs, in the host library built for it.

    Parameters
    ----------
    artifact : Artifact
        The artifact (its library is built and cached on first use).
    library : Path, optional
        A ``libgainlink_host.so`` already built for it.
    watchdog_periods : int
        Idle periods before the safe command.
    """

    def __init__(self, artifact: Any, *, library: Path | None = None, watchdog_periods: int = 10) -> None:
        self.artifact = artifact
        self.library = Path(library or globals()["library"](artifact))
        # The per-step calls take microseconds: through PyDLL they keep the GIL (gainlink.engines.native says why);
        # the block call is long and releases it (CDLL).
        lib = self._lib = ctypes.PyDLL(str(self.library))
        self._run = ctypes.CDLL(str(self.library)).gl_host_law_run
        self._run.argtypes = [_VP, ctypes.c_uint32, _VP, _VP]
        for name in ("gl_host_law_bytes", "gl_host_gains_bytes", "gl_host_record_bytes", "gl_host_sample_bytes"):
            getattr(lib, name).restype = ctypes.c_size_t
        lib.gl_host_artifact_sha256.restype = ctypes.c_char_p
        lib.gl_host_law_name.restype = ctypes.c_char_p
        lib.gl_host_default_gains.restype = _VP
        for name in ("gl_host_law_init", "gl_host_law_step", "gl_host_law_idle", "gl_host_law_reset",
                     "gl_host_law_stage"):  # fmt: skip
            getattr(lib, name).restype = ctypes.c_int32
        lib.gl_host_law_init.argtypes = [_VP, ctypes.c_uint32]
        lib.gl_host_law_step.argtypes = [_VP, _VP, _VP, _VP, _VP]
        lib.gl_host_law_idle.argtypes = lib.gl_host_law_reset.argtypes = [_VP, _VP]
        lib.gl_host_law_stage.argtypes = [_VP, _VP]
        lib.gl_host_law_active_crc32.argtypes = [_VP]
        lib.gl_host_law_active_crc32.restype = ctypes.c_uint32
        sha = lib.gl_host_artifact_sha256().decode()
        if sha != artifact.sha256:
            raise FirmwareError(
                f"library {self.library} was built for artifact {sha[:12]}..., not {artifact.sha256[:12]}..."
            )
        self.sample_dtype = records.sample_layout(artifact).dtype
        self.dtype = records.layout(artifact).dtype
        if (lib.gl_host_record_bytes(), lib.gl_host_sample_bytes()) != (
            self.dtype.itemsize,
            self.sample_dtype.itemsize,
        ):
            raise FirmwareError(f"{self.library}'s records do not match this artifact's law")
        self.law = lib.gl_host_law_name().decode()
        self._law = (ctypes.c_uint64 * ((lib.gl_host_law_bytes() + 7) // 8))()
        self._rec = np.zeros(1, dtype=self.dtype)
        self._sample = np.zeros(1, dtype=self.sample_dtype)
        status = lib.gl_host_law_init(self._law, watchdog_periods)
        if status != 0:
            raise FirmwareError(f"gl_law_init rejected the artifact's gains: {STATUS.get(status, status)}")

    @property
    def address(self) -> int:
        """The address of the law's instance (its first member is the law's own loop: gl_law.h)."""
        return ctypes.addressof(self._law)

    @property
    def last_record(self) -> np.void:
        """The record of the last step, idle period or reset (a copy)."""
        return self._rec.copy()[0]

    def step(self, y: np.ndarray, r: np.ndarray | None = None, s: np.ndarray | None = None) -> np.void:
        """One sample (``y`` p, ``r`` q, ``s`` a scheduled law's external signals e): its record."""
        row = lambda v: None if v is None else np.reshape(v, (1, -1))  # noqa: E731
        self._sample[:] = records.samples(self.artifact, row(y), row(r), row(s))
        at, fields = self._sample.ctypes.data, self.sample_dtype.fields
        self._lib.gl_host_law_step(self._law, at + fields["y"][1], at + fields["r"][1], at + fields["s"][1],
                                   self._rec.ctypes.data)  # fmt: skip
        return self.last_record

    def idle(self) -> np.void:
        """A period without a sample (the watchdog counts it): its record."""
        self._lib.gl_host_law_idle(self._law, self._rec.ctypes.data)
        return self.last_record

    def reset(self) -> np.void:
        """Back to the start state of the set in force: its record."""
        self._lib.gl_host_law_reset(self._law, self._rec.ctypes.data)
        return self.last_record

    def active_crc32(self) -> int:
        """The checksum of the set the law runs."""
        return int(self._lib.gl_host_law_active_crc32(self._law))

    def run(self, Y: np.ndarray, R: np.ndarray | None = None, S: np.ndarray | None = None, *,
            tags: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """A block of samples in one C call, from the current state: one record each (``tags``: a step, an idle
        period or a reset per sample, :data:`gainlink.shipping.records.TAG_STEP` ...)."""
        samples = records.samples(self.artifact, Y, R, S, tags=tags)
        out = np.zeros(samples.size, dtype=self.dtype)
        self._run(self._law, samples.size, samples.ctypes.data, out.ctypes.data)
        return out


class HostLawBlock:
    """``count`` instances of the law ``artifact`` runs, contiguous in one buffer of the host library built for it:
    a campaign block's laws, stepped together in one C call (``gl_host_law_step_block``: instance i takes row i).

    Each instance starts on the artifact's gains (``gl_law_init``) and keeps its own state; the operations per
    instance are those of :meth:`HostLaw.step`, so each row's record equals the one its own instance would give.
    """

    def __init__(self, artifact: Any, count: int, *, library: Path | None = None, watchdog_periods: int = 10) -> None:
        one = HostLaw(artifact, library=library, watchdog_periods=watchdog_periods)  # checks the library's layout
        self.artifact, self.library, self.dtype, self.count = artifact, one.library, one.dtype, int(count)
        lib = ctypes.PyDLL(str(self.library))
        size = lib.gl_host_law_bytes()
        if size % 8:  # rows of uint64 words: the instances' alignment is the buffer's
            raise FirmwareError(f"gl_law_t of {self.library} is {size} bytes, not a whole number of 8-byte words")
        self._laws = np.zeros((self.count, size // 8), dtype=np.uint64)
        self._size = size
        for i in range(self.count):
            status = lib.gl_host_law_init(ctypes.c_void_p(self.address(i)), watchdog_periods)
            if status != 0:
                raise FirmwareError(f"gl_law_init rejected the artifact's gains: {STATUS.get(status, status)}")
        self._block = ctypes.CDLL(str(self.library)).gl_host_law_step_block  # long: releases the GIL
        self._block.argtypes = [_VP, ctypes.c_uint32, _VP, _VP]
        self._out = np.zeros(self.count, dtype=self.dtype)
        self._samples = records.samples(artifact, np.zeros((self.count, artifact.p)))  # TAG_STEP rows, refilled
        self._widths = records.dims(artifact)[2:]  # p, q, e
        self._staged: dict[int, Any] = {}

    def address(self, i: int) -> int:
        """The address of instance ``i``."""
        return self._laws.ctypes.data + i * self._size

    def stage(self, i: int, gains: Any) -> int:
        """``gl_law_stage`` on instance ``i``: its own gain set (a ctypes ``gl_law_gains_t``, kept referenced here:
        the law keeps it by address), in force from its next step. Returns the C status (0: staged)."""
        lib = ctypes.PyDLL(str(self.library))
        lib.gl_host_law_stage.restype = ctypes.c_int32
        lib.gl_host_law_stage.argtypes = [_VP, _VP]
        self._staged[i] = gains
        return int(lib.gl_host_law_stage(self.address(i), ctypes.addressof(gains)))

    def c_block(self) -> dict[str, Any]:
        """What a loop written in C needs to step the block as :meth:`step` does: ``fn`` the address of
        ``gl_host_law_step_block``, ``laws`` the instances, ``samples`` the sample records it fills (float32, a step
        each) and ``records`` the records the call answers (arrays held here, their addresses valid as long as this
        block lives), ``widths`` the law's (p, q, e)."""
        return {"fn": ctypes.cast(self._block, _VP).value, "laws": self._laws, "samples": self._samples,
                "records": self._out, "widths": self._widths}  # fmt: skip

    def step(self, Y: np.ndarray, R: np.ndarray | None = None, S: np.ndarray | None = None) -> np.ndarray:
        """One sample per instance (row i of ``Y`` (count, p), ``R``, ``S`` to instance i): their records (a view
        overwritten by the next call)."""
        samples = self._samples  # filled in place as records.samples fills a new one (float32, missing ones zero)
        with np.errstate(over="ignore"):  # beyond float32 is inf, as on the wire: the law's fault path answers it
            for name, values, width in zip("yrs", (Y, R, S), self._widths):
                if width:
                    samples[name][:, :width] = 0.0 if values is None else np.reshape(values, (self.count, width))
        self._block(self._laws.ctypes.data, self.count, samples.ctypes.data, self._out.ctypes.data)
        return self._out
