"""The fit of every point of a trimmed schedule (``gainlink linearize FMU --schedule``): at each point the check
a single-point ``linearize`` makes (:func:`~.validity.check_linearization`: the interface runs at ``Ts`` will
use, and the FMU and the point's linear model driven by the same small input steps from the trim).

The scheduled spec holds what is shared in its ``[linearization]`` table (FMU, hash, method, ``Ts``, the
interface and why) and each point's fit next to that point's plant, in its ``[[schedule.plant]]`` entry, under
the same keys the single-point record uses (:data:`POINT_KEYS`). A poor fit at a point warns in one line naming
the point.

It checks a plant (the FMU against its linearisations at several trim points), not a law: whatever law is later
designed on the points, so it is named for the points it fits.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .fmi import read_description
from .validity import Validity, check_linearization

log = logging.getLogger(__name__)

#: The keys of a linearisation record that belong to one point (the rest is shared by every point).
POINT_KEYS = ("fit_steps", "fit_amplitude", "fit", "fit_warning")


@dataclass(frozen=True)
class PointFit:
    """One point's check: sigma's name and value, and the :class:`~.validity.Validity` there."""

    sigma: str
    value: float
    validity: Validity

    def record(self) -> dict:
        """The point's part of the record (:data:`POINT_KEYS`; its warning names the point), for its
        ``[[schedule.plant]]`` entry."""
        rec = {k: v for k, v in self.validity.record.items() if k in POINT_KEYS}
        return rec | ({"fit_warning": self.warning()} if self.warning() else {})

    def warning(self) -> str | None:
        """One line for a poor fit, naming the point (None for a good one)."""
        w = self.validity.warning()
        return None if w is None else f"at {self.sigma} = {self.value:g}: {w}"


def fit_schedule(trims: Sequence[Any], *, sigma: str, path: Path, Ts: float, interface: str) -> list[PointFit]:
    """Check each trim's linearisation against the FMU at ``path`` (``interface`` forces one, as for
    ``linearize``); a poor fit at a point is logged as one warning line naming the point."""
    md = read_description(path)
    fits = [
        PointFit(sigma, t.sigma, check_linearization(t.lin, path=path, md=md, Ts=Ts, interface=interface))
        for t in trims
    ]
    for f in fits:
        if f.warning():
            log.warning("FMU %s %s", trims[0].lin.model_name, f.warning())
    return fits


def shared_record(fits: Sequence[PointFit]) -> dict:
    """The scheduled spec's ``[linearization]``: the record without the per-point keys (the first point's;
    the interface verdict is cached per FMU and step, so every point has the same)."""
    return {k: v for k, v in fits[0].validity.record.items() if k not in POINT_KEYS}
