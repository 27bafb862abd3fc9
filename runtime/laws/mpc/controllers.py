"""The MPC law's controllers (:class:`gainlink.laws.base.Controller`): its algorithm in an arithmetic, and the host C;
and the C's records as a trace."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..base import Step
from .step import MpcLoop, MpcTrace


class MpcController:
    """An :class:`~.step.MpcLoop` as a :class:`Controller`."""

    def __init__(self, loop: MpcLoop, describe: dict) -> None:
        self.loop, self.describe = loop, describe
        self.last = None

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample (``s`` unused: the MPC law is not scheduled)."""
        res = self.last = self.loop.step(y, r)
        return Step(u=np.asarray(res.u, dtype=float), flags=res.flags, sat=res.sat)

    def reset(self) -> None:
        """Back to the start state."""
        self.loop.reset()

    def state(self) -> np.ndarray:
        """``xh, z`` and the warm start (:meth:`.step.MpcLoop.state`)."""
        return self.loop.state()


class MpcNative:
    """The host C's MPC law (:class:`~gainlink.firmware.host.HostLaw`) as a :class:`Controller`."""

    def __init__(self, artifact: Any, *, library: Any = None) -> None:
        from ...firmware.host import HostLaw

        self.host = HostLaw(artifact, library=library)
        self.describe = {"kind": "firmware (host C MPC law, ctypes)", "library": str(self.host.library)}

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample through ``gl_mpc_step``: its record's flags are the status flags."""
        rec = self.host.step(y, r)
        return Step(u=rec["u"].astype(float), flags=int(rec["flags"]), sat=int(rec["sat"]))

    def reset(self) -> None:
        """``gl_law_reset``."""
        self.host.reset()

    def state(self) -> np.ndarray:
        """The C's whole state as its last record carries it (``xh, z`` and the warm start)."""
        return np.asarray(self.host.last_record["state"], dtype=float)


def trace_of_records(rec: np.ndarray) -> MpcTrace:
    """The C's records (:func:`gainlink.shipping.records.layout` of the MPC law) as a trace."""
    return MpcTrace(u=rec["u"].astype(float), sat=rec["sat"].astype(np.int64), flags=rec["flags"].astype(np.int64),
                    iterations=rec["iters"].astype(np.int64), state=rec["state"].astype(float))  # fmt: skip
