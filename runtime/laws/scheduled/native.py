"""The host build of the scheduled C loop (``firmware/src/gl_sched.c``), driven through ctypes.

:class:`NativeScheduledLoop` owns the scheduled law's instance (:class:`gainlink.firmware.host.HostLaw`, whose first
member is a ``gl_sched_t``); :meth:`NativeScheduledLoop.run` hands a block of samples to the library in one call and
returns a :class:`~gainlink.laws.scheduled.reference.ScheduledTrace` (float32 values as float64 arrays).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from ...errors import FirmwareError
from ...firmware.host import HostLaw
from ...shipping import flags
from ...shipping.artifact import Artifact
from .reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE, ScheduledTrace

_FP = ctypes.POINTER(ctypes.c_float)
#: The status flags of the record and the scheduled law's own sigma flags (laws.scheduled.reference).
_SIGMA = ((flags.SIGMA_HELD, SIGMA_HELD), (flags.SIGMA_CLIPPED, SIGMA_CLIPPED), (flags.SIGMA_RATE, SIGMA_RATE))
_SIGMA_LOW = min(bit for bit, _ in _SIGMA).bit_length() - 1
_SIGMA_SPAN = max(bit for bit, _ in _SIGMA).bit_length() - _SIGMA_LOW
#: The own flags of each value of the record's flag bits _SIGMA_LOW .. + _SIGMA_SPAN (one lookup per record).
_SIGMA_OWN = np.array([sum(own for bit, own in _SIGMA if (k << _SIGMA_LOW) & bit) for k in range(1 << _SIGMA_SPAN)])


def state_length(a: Artifact) -> int:
    """``GL_SCHED_STATE_LEN``: delta, u_prev, y_prev, e_prev, sigma, sigma_f, started."""
    return a.n + a.m + a.p + a.q + 3


def sigma_flags(status_flags: np.ndarray) -> np.ndarray:
    """The scheduled law's own sigma flags of records' status flags."""
    status_flags = np.asarray(status_flags, dtype=np.int64)
    return _SIGMA_OWN[(status_flags >> _SIGMA_LOW) & ((1 << _SIGMA_SPAN) - 1)]


def raw_of_records(rec: np.ndarray) -> dict[str, np.ndarray]:
    """The records of a scheduled law as the arrays :func:`scheduled_trace_from_raw` takes: views of the records (a
    copy of the state column alone would cost as much as the step)."""
    return {"u": rec["u"], "sat": rec["sat"], "sflags": sigma_flags(rec["flags"]), "state": rec["state"],
            "status": rec["status"]}  # fmt: skip


class NativeScheduledLoop:
    """One instance of the scheduled law in the host library built for the scheduled ``artifact``.

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
        self.host = HostLaw(artifact, library=library)
        self.library = self.host.library
        lib = self._lib = ctypes.PyDLL(str(self.library))  # short calls keep the GIL (see gainlink.engines.native)
        self._loop = self.host.address  # a gl_sched_t first: the law's own functions take it
        lib.gl_sched_init.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.gl_sched_reset.argtypes = [ctypes.c_void_p]
        lib.gl_sched_state.argtypes = [ctypes.c_void_p, _FP]

    def reset(self) -> int:
        """Back to the start state (``gl_law_reset``)."""
        return int(self.host.reset()["status"])

    def state(self) -> np.ndarray:
        """``gl_sched_state``: the loop's state vector (float32)."""
        out = np.zeros(state_length(self.artifact), np.float32)
        self._lib.gl_sched_state(self._loop, out.ctypes.data_as(_FP))
        return out

    def run_raw(self, Y, R=None, S=None) -> dict[str, np.ndarray]:
        """Run a block in one C call; float32 outputs ``u sat sflags state status`` (views of one record array)."""
        return raw_of_records(self.host.run(Y, R, S if self.e else None))

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
