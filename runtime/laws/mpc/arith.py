"""The two arithmetics the MPC law is written once for: float64 (the algorithm's model) and the C's float32 (every
``+ - *`` correctly rounded to float32, every multiply-add one correctly rounded ``fmaf``), both on numpy arrays.

The law's step (:mod:`.solver`, :mod:`.step`) is written against :class:`Arith`, so the float64 model and the bit-exact
model of the C are the same sequence of operations in the same order, and only the rounding differs. Sums are chains:
``acc = start; acc = fma(a_j, b_j, acc)`` for each term in order (the order ``firmware/src/gl_mpc.c`` keeps); a chain
over the columns of a matrix runs every row's chain at once (each element's chain is its own). The float64 model
sums a matrix product in numpy's order: it models the algorithm, not an arithmetic.
"""

from __future__ import annotations

import numpy as np

from ..lq.model import fma32_exact
from ..lq.step import MID_HALF, MID_MASK


class Arith:
    """float64: numpy's own operations."""

    name = "float64"

    def value(self, x) -> np.ndarray:
        """``x`` as this arithmetic's numbers (float64 arrays)."""
        return np.array(x, dtype=np.float64)

    def fma(self, a, b, c) -> np.ndarray:
        """``a * b + c`` element-wise."""
        return a * b + c

    def add(self, a, b) -> np.ndarray:
        return a + b

    def sub(self, a, b) -> np.ndarray:
        return a - b

    def mul(self, a, b) -> np.ndarray:
        return a * b

    def matvec(self, M: np.ndarray, x: np.ndarray, acc: np.ndarray) -> np.ndarray:
        """``acc + M x`` (float64: numpy's product, in its own order; the algorithm's model, not an arithmetic's)."""
        return acc + M @ x


class Float32(Arith):
    """The C's float32 arithmetic, values held in float64 arrays (exactly representable in float32)."""

    name = "float32"

    @staticmethod
    def _round(s) -> np.ndarray:
        return np.asarray(s, dtype=np.float64).astype(np.float32).astype(np.float64)

    def value(self, x) -> np.ndarray:
        return self._round(x)

    def matvec(self, M: np.ndarray, x: np.ndarray, acc: np.ndarray) -> np.ndarray:
        """``acc + M x``, each row's chain of ``fmaf`` over the columns in order (the C's)."""
        for j in range(M.shape[1]):
            acc = self.fma(M[:, j], x[j], acc)
        return acc

    def fma(self, a, b, c) -> np.ndarray:
        """Correctly rounded ``fmaf``: the product of two float32 values is exact in float64, so the float64 sum
        rounded to float32 is ``fmaf`` unless the float64 sum lies on a float32 midpoint (then redone exactly)."""
        a, b, c = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64), np.asarray(c, np.float64))
        s = a * b + c
        r = self._round(s)
        mid = (s != r) & ((s.view(np.uint64) & MID_MASK) == MID_HALF)
        if mid.any():
            r = np.array(r)
            for i in zip(*np.nonzero(mid)):
                r[i] = fma32_exact(float(a[i]), float(b[i]), float(c[i]))
        return r

    def add(self, a, b) -> np.ndarray:
        return self._round(np.asarray(a, np.float64) + b)  # the float64 sum of two float32 rounds once correctly

    def sub(self, a, b) -> np.ndarray:
        return self._round(np.asarray(a, np.float64) - b)

    def mul(self, a, b) -> np.ndarray:
        return self._round(np.asarray(a, np.float64) * b)  # exact in float64, one rounding
