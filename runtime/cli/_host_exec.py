"""Replaying samples through a host loop executable (the float32 ``gainlink_loop_host`` or the integer
``gainlink_fixed_loop_host``): one line of samples and references per step in, the executable's answer out."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from ..errors import FirmwareError


def answer_samples(exe: Path, Y: np.ndarray, R: np.ndarray) -> tuple[str, int]:
    """The executable's whole stdout for the steps ``Y[k], R[k]`` (one line each), and the number of steps.

    Raises
    ------
    FirmwareError
        The executable exited with a non-zero status (its stderr's start in the message).
    """
    lines = [" ".join(repr(float(v)) for v in np.concatenate([Y[k], R[k]])) for k in range(Y.shape[0])]
    proc = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        raise FirmwareError(f"host firmware exited with status {proc.returncode}: {proc.stderr.strip()[:200]}")
    return proc.stdout, len(lines)
