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
    """A law's image and its record stream (``firmware/ports/cortex-m/main.c``, one main for every law; the stream
    of ``gl_stream.h``): the input header ``<4I in_magic, steps, 1 record per block, watchdog>``, the output header
    ``<8I out_magic, steps, *header>`` (``header``: the law's id and its dimensions n, m, p, q, e,
    :func:`gainlink.firmware.qemu.output_header`), one input record ``din`` (``tag``, ``y``, ``r``, ``s``:
    :func:`gainlink.shipping.records.sample_layout`) and one output record ``dout`` per step (the law's record,
    :func:`gainlink.shipping.records.layout`), which :attr:`decode` turns into the law's
    :class:`~gainlink.laws.base.Step`; ``symbol`` is the law's step function in the image, what an instruction count
    covers (:func:`gainlink.shipping.law_c.step_symbol`)."""

    elf: Path
    in_magic: int
    out_magic: int
    header: tuple[int, ...]
    din: np.dtype
    dout: np.dtype
    decode: Callable[[Any], Any]
    symbol: str
    watchdog: bool = True  # the header's last word is the watchdog's periods (else 0)

    def sample(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> bytes:
        """One input record for the sample ``y``, ``r``, ``s`` (cast to float32; tagged a step)."""
        rec = np.zeros(1, dtype=self.din)  # tag 0: TAG_STEP
        rec["y"] = np.asarray(y, dtype=np.float32)
        if r.size:
            rec["r"][0, : r.size] = np.asarray(r, dtype=np.float32)
        if s.size:
            rec["s"][0, : s.size] = np.asarray(s, dtype=np.float32)
        return rec.tobytes()


def law_image_stream(artifact: Any, *, target: str, board: str, decode: Callable[[Any], Any]) -> ImageStream:
    """The replay-only image of ``artifact``'s law on ``target``/``board`` (built and cached:
    :func:`gainlink.firmware.build.replay_image`, the same image for every law) and its stream, its records read by
    the law's ``decode``."""
    from ..firmware import qemu as fwqemu
    from ..firmware.build import replay_image
    from ..shipping import records
    from ..shipping.law_c import step_symbol

    elf = replay_image(artifact, target=target, board=board)
    return ImageStream(elf=elf, in_magic=fwqemu.IN_MAGIC, out_magic=fwqemu.OUT_MAGIC,
                       header=fwqemu.output_header(artifact), din=records.sample_layout(artifact).dtype,
                       dout=records.layout(artifact).dtype, decode=decode,
                       symbol=step_symbol(artifact))  # fmt: skip


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
