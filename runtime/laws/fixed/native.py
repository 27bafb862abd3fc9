"""The host build's fixed-point law stepped one sample at a time (software in the loop of a fixed-point artifact):
the integer law the artifact certifies, with the step interface of :class:`~gainlink.engines.native.NativeLoop`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...engines.native import StepOutput
from ...firmware.host import HostLaw
from ...shipping.artifact import Artifact
from . import firmware as fwfixed


class FixedNativeLoop:
    """One instance of the integer law in the host library built for ``artifact`` (``numeric = "q31"|"q15"``).

    Parameters
    ----------
    artifact : Artifact
        A fixed-point artifact (its library is built and cached on first use).
    library : Path, optional
        Its ``libgainlink_host.so``, already built.
    """

    def __init__(self, artifact: Artifact, *, library: Path | None = None) -> None:
        fwfixed.require_fixed(artifact)
        self.a = artifact
        self.host = HostLaw(artifact, library=Path(library or fwfixed.host_library(artifact)))
        self.library = self.host.library

    @property
    def last_record(self) -> np.void:
        """The C's record of the last step (:func:`gainlink.shipping.records.layout`: flags, words, ...)."""
        return self.host.last_record

    @property
    def law(self) -> str:
        """``q31`` or ``q15``."""
        return self.host.law

    def step(self, y: np.ndarray, r: np.ndarray | None = None) -> StepOutput:
        """One step on sample ``y`` and references ``r``: the float command, the step's status code and the
        saturation mask."""
        rec = self.host.step(y, r if self.a.q else None)
        return StepOutput(u=rec["u"].astype(np.float64), status=int(rec["status"]), sat_mask=int(rec["sat"]))

    def reset(self) -> None:
        """Back to the initial state."""
        self.host.reset()
