"""A law stepped for a whole campaign block (:mod:`gainlink.hil.campaign`): many instances of one build, each with
its own state (and gain set), one sample each per step.

- :class:`NativeBlock`: every instance in one buffer of the host library, stepped by one C call per step
  (``gl_host_law_step_block``, :class:`gainlink.firmware.host.HostLawBlock`); any law the host library builds.
- :class:`OneByOne`: a list of the law's controllers, each stepped in turn (the fallback for what cannot step in
  one call: the float64 reference, a law whose host build is not at hand).

A family may step its float64 law as columns (the lq law's :class:`gainlink.laws.lq.block.ReferenceBlock`).

Both answer :meth:`step` with a :class:`BlockStep`: row i is what instance i's own
:meth:`~gainlink.laws.base.Controller.step` returns (the same values, bit for bit, for the same samples).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from . import flags as status_flags


@dataclass(frozen=True)
class BlockStep:
    """One step of a block: row i is instance i's :class:`~gainlink.laws.base.Step` (``u`` (B, m) float64 holding
    the C's float32, ``flags`` and ``sat`` (B,), ``sigma`` (B,); ``sigma`` None for a law without one: every
    instance's is NaN, and a block records none)."""

    u: np.ndarray
    flags: np.ndarray
    sat: np.ndarray
    sigma: np.ndarray | None


class NativeBlock:
    """``count`` instances of the host C of ``artifact``'s law, one C call per step (module docstring)."""

    vectorised = True

    def __init__(self, artifact: Any, count: int, *, library: Any = None) -> None:
        from ..firmware.host import HostLawBlock

        self.host = HostLawBlock(artifact, count, library=library)
        self.describe = {"kind": "firmware (host C, a block of instances, ctypes)", "library": str(self.host.library)}
        self._sigma = "sigma" in self.host.dtype.names

    def c_law(self) -> dict[str, Any]:
        """How a loop written in C steps this block as :meth:`step` does (``gainlink.hil.loop.lockstep``: kind 0,
        ``gl_host_law_step_block`` of the host library, the byte offsets of the sample's and the record's fields;
        ``sigma_off`` -1 for a law without sigma, ``records_sigma`` whether the loop records it; ``fault`` the flag
        that zeroes the saturation mask)."""
        c = self.host.c_block()
        ins, outs = c["samples"].dtype.fields, c["records"].dtype.fields
        _, q, e = c["widths"]
        return {"kind": 0, "fn": c["fn"], "laws": c["laws"], "law_bytes": c["laws"].strides[0],
                "samples": c["samples"], "records": c["records"],
                "sample_bytes": c["samples"].dtype.itemsize, "y_off": ins["y"][1], "r_off": ins["r"][1] if q else 0,
                "s_off": ins["s"][1] if e else 0, "law_q": q, "law_e": e, "record_bytes": c["records"].dtype.itemsize,
                "flags_off": outs["flags"][1], "sat_off": outs["sat"][1], "u_off": outs["u"][1],
                "sigma_off": outs["sigma"][1] if self._sigma else -1, "records_sigma": self._sigma,
                "fault": status_flags.FAULT}  # fmt: skip

    def step(self, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> BlockStep:
        """Row i of ``Y``, ``R``, ``S`` to instance i."""
        rec = self.host.step(Y, R if R.shape[1] else None, S if S.shape[1] else None)
        bits = rec["flags"].astype(np.int64)
        sat = np.where(bits & status_flags.FAULT, 0, rec["sat"]).astype(np.int64)  # a faulted step clamps nothing
        sigma = rec["sigma"].astype(float) if self._sigma else None
        return BlockStep(u=rec["u"].astype(float), flags=bits, sat=sat, sigma=sigma)


class OneByOne:
    """Instances stepped one after the other through their own ``step`` (module docstring)."""

    vectorised = False

    def __init__(self, controllers: list[Any]) -> None:
        self.controllers = controllers
        self.describe = dict(controllers[0].describe) if controllers else {}

    def step(self, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> BlockStep:
        """Row i of ``Y``, ``R``, ``S`` to controller i."""
        steps = [c.step(Y[i], R[i], S[i]) for i, c in enumerate(self.controllers)]
        return BlockStep(
            u=np.array([s.u for s in steps], dtype=float).reshape(len(steps), -1),
            flags=np.array([s.flags for s in steps], dtype=np.int64),
            sat=np.array([s.sat for s in steps], dtype=np.int64),
            sigma=np.array([s.sigma for s in steps], dtype=float),
        )

    def states(self) -> np.ndarray:
        """Each controller's ``state()`` after its last step, as rows."""
        return np.array([c.state() for c in self.controllers], dtype=float)
