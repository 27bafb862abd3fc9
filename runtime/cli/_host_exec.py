"""Replaying samples through the host loop executable ``gainlink_loop_host`` (whichever law it runs): one line of
samples and references per step in, the executable's answer out, one ``step`` line per step holding the law's record
(:mod:`gainlink.shipping.records`)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from ..errors import FirmwareError
from ..shipping import records


def answer_samples(exe: Path, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None = None) -> tuple[str, int]:
    """The executable's whole stdout for the steps ``Y[k], R[k]`` (and a scheduled law's external signals ``S[k]``
    after them: the sample line of ``firmware/ports/host/main.c``; one line each), and the number of steps.

    Raises
    ------
    FirmwareError
        The executable exited with a non-zero status (its stderr's start in the message).
    """
    S = np.zeros((Y.shape[0], 0)) if S is None else np.asarray(S, dtype=float).reshape(Y.shape[0], -1)
    lines = [" ".join(repr(float(v)) for v in np.concatenate([Y[k], R[k], S[k]])) for k in range(Y.shape[0])]
    proc = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        raise FirmwareError(f"host firmware exited with status {proc.returncode}: {proc.stderr.strip()[:200]}")
    return proc.stdout, len(lines)


def parse_records(artifact, stdout: str, *, count: int, executable: str) -> np.ndarray:
    """The executable's answer to ``count`` sample lines: its banner must name ``artifact``, then one ``step`` line
    each, read as the law's records."""
    out = stdout.splitlines()
    if not out or not out[0].startswith(f"gainlink-loop {artifact.name} sha256:{artifact.sha256}"):
        raise FirmwareError(
            f"{executable} was not built for artifact {artifact.name} (banner {out[0] if out else ''!r})"
        )
    steps = out[1:]
    bad = next((k for k, ln in enumerate(steps) if not ln.startswith("step ")), None)
    if bad is not None or len(steps) != count:
        where = f"line {bad + 1} is {steps[bad][:60]!r}" if bad is not None else f"{len(steps)} lines"
        raise FirmwareError(f"{executable} answered {count} samples unexpectedly: {where}")
    try:
        return records.layout(artifact).from_text([ln.split()[1:] for ln in steps])
    except ValueError as exc:
        raise FirmwareError(f"{executable} answered unexpectedly: {exc}") from None
