"""The lq law's float64 reference stepped for a whole campaign block, as columns (:mod:`gainlink.laws.block`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import flags as status_flags
from ..block import BlockStep


class ReferenceBlock:
    """``count`` instances of the lq structure's float64 law (:class:`gainlink.proof.reference.ReferenceLoop`) as
    columns: the law's generated step over the block (:func:`gainlink.proof.reference_step.compile_reference_block`),
    each column what its own reference answers, bit for bit. A run whose sample is not finite is refused as the
    reference refuses it (the safe command, its state kept)."""

    vectorised = True

    def __init__(self, artifact: Any, count: int) -> None:
        from ...proof.reference_step import compile_reference_block

        a = self.a = artifact
        self._step = compile_reference_block(a)
        self.xh = np.repeat(np.asarray(a.xh0, float)[:, None], count, axis=1)  # (n, B)
        self.z = np.repeat(np.asarray(a.z0, float)[:, None], count, axis=1)  # (q, B)
        self.safe = np.asarray(a.safe_command, float)
        self._weights = (1 << np.arange(np.size(a.u_min), dtype=np.int64))[:, None]  # input j: bit j of the mask
        self.describe = {"kind": "reference (float64 law, a block of columns)"}

    def step(self, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> BlockStep:
        """Row i of ``Y`` (B, p), ``R`` (B, q) to run i (``S`` unused: this law is not scheduled)."""
        B = Y.shape[0]
        Yt, Rt = np.asarray(Y, float).T, np.asarray(R, float).reshape(B, -1).T
        ok = np.isfinite(Yt).all(axis=0) & np.isfinite(Rt).all(axis=0)
        every = bool(ok.all())  # the common case: nothing refused, nothing to put back
        with np.errstate(all="ignore"):  # refused columns compute garbage, then are replaced
            u, _v, sat, xh, z = self._step(self.xh, self.z, Yt, Rt if self.a.q else np.zeros((0, B)))
        U = np.array(u, float).reshape(-1, B).T
        if xh:
            self.xh = np.array(xh, float) if every else np.where(ok, np.array(xh, float), self.xh)
        if z:
            self.z = np.array(z, float) if every else np.where(ok, np.array(z, float), self.z)
        bits = np.array(sat, dtype=bool).reshape(-1, B)
        sat_mask = (bits.astype(np.int64) * self._weights[: bits.shape[0]]).sum(axis=0)
        if every:
            return BlockStep(u=U, flags=np.zeros(B, dtype=np.int64), sat=sat_mask, sigma=None)  # not scheduled
        U = np.where(ok[:, None], U, self.safe)
        flags = np.where(ok, 0, status_flags.FAULT).astype(np.int64)
        return BlockStep(u=U, flags=flags, sat=np.where(ok, sat_mask, 0), sigma=None)

    def states(self) -> np.ndarray:
        """Each run's ``[xh, z]`` (the reference's ``state()``), as rows."""
        return np.concatenate([self.xh, self.z], axis=0).T
