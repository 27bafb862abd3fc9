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
        self.describe = {"kind": "reference (float64 law, a block of columns)"}

    def step(self, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> BlockStep:
        """Row i of ``Y`` (B, p), ``R`` (B, q) to run i (``S`` unused: this law is not scheduled)."""
        Yt, Rt = np.asarray(Y, float).T, np.asarray(R, float).reshape(Y.shape[0], -1).T
        ok = np.isfinite(Yt).all(axis=0) & np.isfinite(Rt).all(axis=0)
        with np.errstate(all="ignore"):  # refused columns compute garbage, then are replaced
            u, _v, sat, xh, z = self._step(self.xh, self.z, Yt, Rt if self.a.q else np.zeros((0, Y.shape[0])))
        U = np.where(ok[:, None], np.array(u, float).reshape(-1, Y.shape[0]).T, self.safe)
        if xh:
            self.xh = np.where(ok, np.array(xh, float), self.xh)
        if z:
            self.z = np.where(ok, np.array(z, float), self.z)
        bits = np.array(sat, dtype=bool).reshape(-1, Y.shape[0])
        weights = (1 << np.arange(bits.shape[0], dtype=np.int64))[:, None]
        sat_mask = np.where(ok, (bits.astype(np.int64) * weights).sum(axis=0), 0)
        flags = np.where(ok, 0, status_flags.FAULT).astype(np.int64)
        return BlockStep(u=U, flags=flags, sat=sat_mask, sigma=None)  # not scheduled

    def states(self) -> np.ndarray:
        """Each run's ``[xh, z]`` (the reference's ``state()``), as rows."""
        return np.concatenate([self.xh, self.z], axis=0).T
