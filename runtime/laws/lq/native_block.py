"""The lq law's float64 reference over a campaign block in one C call per step (``native/reference_block.c``, built
on first use by :mod:`gainlink.firmware.c_kernel`): each instance's numbers are its own
:class:`~gainlink.proof.reference.ReferenceLoop`'s bit for bit (the C file says how). The Python stays the reference,
and the block's path for a law wider than the C's buffers (:func:`covers`: :class:`.block.ReferenceBlock`)."""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path
from typing import Any

import numpy as np

from .. import flags as status_flags
from ..block import BlockStep

SOURCE = Path(__file__).resolve().parent / "native" / "reference_block.c"
LIBRARY = "libgainlink_reference_block.so"
#: the artifact's arrays the C reads, in the order of its ``mats`` (then the safe command and Ts)
MATS = ("y_op", "u_op", "u_min", "u_max", "K", "Ki", "M", "Cd", "Ci", "Kaw", "Ad", "Bd", "Dd", "L")
AW = {"none": 0, "clamp": 1, "backcalc": 2}
_P = ctypes.c_void_p


@functools.cache
def _kernel() -> tuple[ctypes._CFuncPtr, int]:
    from ...firmware.c_kernel import kernel_library, loaded

    lib = loaded(kernel_library(SOURCE, name=LIBRARY, what="the float64 law's block step"))
    fn = lib.gl_ref_block
    fn.argtypes = [_P, _P, ctypes.c_int64, _P, _P, ctypes.c_int64, _P, ctypes.c_int64, _P, _P, _P]
    fn.restype = None
    lib.gl_ref_max.restype = ctypes.c_int64
    return fn, int(lib.gl_ref_max())


def covers(artifact: Any) -> bool:
    """Whether the C steps ``artifact``'s law (its widths within the C's buffers; the kernel built, or a one-line
    :class:`~gainlink.errors.ToolchainError`)."""
    a = artifact
    return max(a.n, a.m, a.p, a.q) <= _kernel()[1] and a.anti_windup in AW


class NativeReferenceBlock:
    """``count`` instances of the lq structure's float64 law, stepped by one C call per step; each row what its own
    reference answers (a sample or reference that is not finite refused as the reference refuses it: the safe
    command, the state kept)."""

    vectorised = True

    def __init__(self, artifact: Any, count: int) -> None:
        a = artifact
        self._fn = _kernel()[0]
        self.state = np.empty((count, a.n + a.q))  # row i: instance i's [xh, z]
        self.state[:, : a.n], self.state[:, a.n :] = a.xh0, a.z0
        form = {"current": 1, "predictor": 0}[a.observer_form]
        self._dims = np.array([a.n, a.m, a.p, a.q, form, AW[a.anti_windup]], dtype=np.int64)
        arrays = [getattr(a, name) for name in MATS] + [a.safe_command, [a.Ts]]
        self._mats = [np.ascontiguousarray(x, dtype=np.float64) for x in arrays]  # kept: the C holds their addresses
        self._table = np.array([x.ctypes.data for x in self._mats], dtype=np.uintp)
        self._zeros = np.zeros(1)  # the reference of a law without integrators: never read
        self.m, self.q = a.m, a.q
        self.describe = {"kind": "reference (float64 law, a block in one C call)"}

    def c_law(self) -> dict[str, Any]:
        """How a loop written in C steps this block as :meth:`step` does (``gainlink.hil.loop.lockstep``: kind 1,
        ``gl_ref_block`` on this block's dims, matrices and states; the float64 law records no sigma)."""
        return {"kind": 1, "fn": ctypes.cast(self._fn, ctypes.c_void_p).value, "dims": self._dims,
                "mats": self._table, "state": self.state, "state_width": self.state.shape[1], "law_q": self.q,
                "records_sigma": False, "fault": status_flags.FAULT}  # fmt: skip

    def step(self, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> BlockStep:
        """Row i of ``Y`` (B, p), ``R`` (B, q) to instance i (``S`` unused: this law is not scheduled)."""
        B = len(self.state)
        Y = _rows(Y)
        R = _rows(R) if self.q else self._zeros
        r_row = R.strides[0] // 8 if self.q else 0
        u, sat, refused = np.empty((B, self.m)), np.empty(B, np.int64), np.empty(B, np.int64)
        self._fn(self._dims.ctypes.data, self._table.ctypes.data, B, self.state.ctypes.data, Y.ctypes.data,
                 Y.strides[0] // 8, R.ctypes.data, r_row, u.ctypes.data, sat.ctypes.data,
                 refused.ctypes.data)  # fmt: skip
        return BlockStep(u=u, flags=refused * status_flags.FAULT, sat=sat, sigma=None)

    def states(self) -> np.ndarray:
        """Each instance's ``[xh, z]`` (the reference's ``state()``), as rows (the block's own buffer)."""
        return self.state


def _rows(X: np.ndarray) -> np.ndarray:
    """``X`` (B, width) float64 whose rows are each contiguous (a row stride of 0, one row shared, kept)."""
    if X.dtype == np.float64 and (X.shape[1] <= 1 or X.strides[1] == 8) and X.strides[0] % 8 == 0:
        return X
    return np.ascontiguousarray(X, dtype=np.float64)
