"""Fault injection between the loop and its endpoint: on the sample's values (nan: every measured output of the
sample sent as NaN; in process too) and on a link's frames (drop, delay, duplicate, reorder)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .scenario import Fault

#: Faults on the process (the bridge pauses or kills the peer) and on the sample's values (:meth:`corrupt`).
PROCESS_FAULTS = ("silent", "crash")
SAMPLE_FAULTS = ("nan",)


class FaultInjector:
    """Decides, per sample, which frames go out now.

    Parameters
    ----------
    faults : sequence of Fault
        The scenario's faults: the frame faults act in :meth:`apply`, ``nan`` in :meth:`corrupt` (``silent`` and
        ``crash`` act on the process: the bridge handles them).
    Ts : float
        Sample time, to turn fault windows into sample indices.
    seed : int
        Seeds the draws of faults with a ``probability`` below 1 (the same seed hits the same samples).
    """

    def __init__(self, faults: Sequence[Fault], *, Ts: float, seed: int = 0) -> None:
        self.faults = [f for f in faults if f.kind not in PROCESS_FAULTS + SAMPLE_FAULTS]
        self.sample_faults = [f for f in faults if f.kind in SAMPLE_FAULTS]
        self.Ts = Ts
        self.seed = int(seed)
        self._rng: np.random.Generator | None = None
        self.held: list[tuple[int, int, Any]] = []  # (release at sample, sample, unit)
        self.counts = {"drop": 0, "delay": 0, "duplicate": 0, "reorder": 0}
        if self.sample_faults:  # only then: a report without them reads as before
            self.counts["nan"] = 0

    @property
    def rng(self) -> np.random.Generator:
        """The stream of the faults' draws: its own (not the noise's), so adding a fault leaves the run's noise
        unchanged; seeded on first use (seeding costs more than a campaign run's step, and most runs draw none)."""
        if self._rng is None:
            self._rng = np.random.default_rng([self.seed & 0xFFFFFFFF, 0xFA17])
        return self._rng

    def _hits(self, f: Fault, k: int) -> bool:
        """Whether fault ``f`` hits sample ``k``: in its window, on its ``every``-th sample, with its probability."""
        if not f.start <= k * self.Ts < f.stop:
            return False
        first = int(round(f.start / self.Ts)) if f.start > 0 else 0
        return (k - first) % f.every == 0 and (f.probability >= 1.0 or self.rng.random() < f.probability)

    def _active(self, k: int) -> Fault | None:
        return next((f for f in self.faults if self._hits(f, k)), None)

    def corrupt(self, k: int, y: np.ndarray) -> np.ndarray:
        """The measured outputs sample ``k`` carries: ``y``, or all NaN when a ``nan`` fault hits it (counted)."""
        if not any(self._hits(f, k) for f in self.sample_faults):
            return y
        self.counts["nan"] += 1
        return np.full_like(np.asarray(y, dtype=float), np.nan)

    def apply(self, k: int, unit: Any) -> list[tuple[int, Any]]:
        """What goes out at sample ``k``: ``(sample, unit)`` pairs in sending order, ``unit`` being sample ``k``'s
        (its frames, or anything that stands for them); held units due now come after this sample's own."""
        fault = self._active(k) if self.faults else None
        out: list[tuple[int, Any]] = []
        if fault is None:
            out = [(k, unit)]
        elif fault.kind == "drop":
            self.counts["drop"] += 1
        elif fault.kind == "duplicate":
            self.counts["duplicate"] += 1
            out = [(k, unit), (k, unit)]
        elif fault.kind == "delay":
            self.counts["delay"] += 1
            self.held.append((k + fault.delay_steps, k, unit))
        elif fault.kind == "reorder":
            self.counts["reorder"] += 1
            self.held.append((k + 1, k, unit))
        if self.held:
            out += [(j, u) for at, j, u in self.held if at <= k]
            self.held = [h for h in self.held if h[0] > k]
        return out
