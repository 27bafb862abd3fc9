"""How a loop talks to a law's replay-only Cortex-M image over its semihosting FIFOs (processor in the loop): the
image, the stream's header words and records, and the law's step read from an output record."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ImageStream:
    """A law's image and its record stream (firmware/include/gainlink/gl_stream.h): the input header
    ``<4I in_magic, steps, 1 record per block, watchdog>``, the output header's first word ``out_magic``, one input
    record ``din`` (``y``, ``r``, and ``s`` for a law with external signals) and one output record ``dout`` per step,
    which :attr:`decode` turns into the law's :class:`~gainlink.laws.base.Step`."""

    elf: Path
    in_magic: int
    out_magic: int
    din: np.dtype
    dout: np.dtype
    decode: Callable[[Any], Any]
    watchdog: bool = True  # the header's last word is the watchdog's periods (else 0)

    def sample(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> bytes:
        """One input record for the sample ``y``, ``r``, ``s`` (cast to float32)."""
        rec = np.zeros(1, dtype=self.din)
        rec["y"] = np.asarray(y, dtype=np.float32)
        if r.size:
            rec["r"][0, : r.size] = np.asarray(r, dtype=np.float32)
        if s.size:
            rec["s"][0, : s.size] = np.asarray(s, dtype=np.float32)
        return rec.tobytes()


def first_difference(image: np.ndarray, model: np.ndarray) -> dict | None:
    """The first step whose record differs in its bits, and the first field that does there (None: all equal)."""
    first = None
    for field in image.dtype.names:
        got = image[field].reshape(len(image), -1).view(np.uint32)
        want = model[field].reshape(len(model), -1).view(np.uint32)
        bad = np.flatnonzero(np.any(got != want, axis=1))
        if bad.size and (first is None or bad[0] < first["step"]):
            first = {"step": int(bad[0]), "field": field}
    return first
