"""A scheduled law's external scheduling signals on the command line: ``--schedule-signal NAME=START[,END]``, a
constant or a linear ramp over the run (``gainlink simulate``, ``gainlink pil run``)."""

from __future__ import annotations

import numpy as np

from ..errors import GainlinkError


def parse_signals(items: list[str] | None) -> dict[str, tuple[float, float]]:
    """``NAME=START[,END]`` per ``--schedule-signal``: a constant or a linear ramp over the run."""
    out = {}
    for item in items or ():
        name, _, values = item.partition("=")
        try:
            nums = [float(v) for v in values.split(",")]
        except ValueError:
            nums = []
        if not name or len(nums) not in (1, 2):
            raise GainlinkError(f"--schedule-signal {item!r}: give NAME=START or NAME=START,END (numbers)")
        out[name] = (nums[0], nums[-1])
    return out


def signal_ramps(artifact, items: list[str] | None, steps: int) -> np.ndarray:
    """The law's external scheduling signals per step (steps, e) from ``--schedule-signal`` items: one line when a
    name is not an external signal of the artifact's law, or one is missing."""
    from ..laws import law_of

    names = law_of(artifact).externals(artifact)
    spec = parse_signals(items)
    unknown = sorted(set(spec) - set(names))
    if unknown:
        raise GainlinkError(f"--schedule-signal {unknown[0]}: not an external scheduling signal of {artifact.name} "
                            f"(external: {', '.join(names) or 'none'})")  # fmt: skip
    missing = [n for n in names if n not in spec]
    if missing:
        raise GainlinkError(f"artifact {artifact.name} is scheduled on {', '.join(missing)}: give --schedule-signal "
                            f"{missing[0]}=START[,END]")  # fmt: skip
    return np.column_stack([np.linspace(*spec[n], steps) for n in names] or [np.zeros((steps, 0))])
