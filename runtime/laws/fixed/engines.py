"""The fixed-point C as replay engines: ``native`` and ``qemu`` run it for a fixed-point artifact.

A fixed-point artifact's implementation is the integer law, so ``replay --engine native`` runs the host build of
``firmware/src/gl_fixed.c`` and ``--engine qemu`` its Cortex-M image (:mod:`gainlink.laws.fixed.firmware`); ``fixed``
runs the bit-exact model (:mod:`gainlink.laws.fixed.model`). All three give the same trace, bit for bit: the
command words, estimate and integrators in real units (``X 2**-f``, exact in double), the saturation and fault
flags.
"""

from __future__ import annotations

import numpy as np

from ...firmware.targets import resolve_cortex_m
from ...proof.reference import Trace
from ...shipping.artifact import Artifact
from . import firmware as fwfixed
from .qformat import real


def trace_from_run(a: Artifact, run: fwfixed.FixedRun) -> Trace:
    """The replay trace of a fixed-point run: the integers as the real values they mean."""
    f = a.checks["fixed_point"]["formats"]
    bits = np.arange(a.m)
    return Trace(
        u=real(run.U, np.array(f["u"])),
        saturated=((run.sat[:, None] >> bits[None, :]) & 1).astype(bool),
        xh=real(run.XH, np.array(f["xh"])),
        z=real(run.Z, np.array(f["z"])) if a.q else np.zeros((run.U.shape[0], 0)),
        fault=(run.flags & fwfixed.FAULT) != 0,
    )


def run_native(artifact: Artifact, Y: np.ndarray, R: np.ndarray) -> Trace:
    """``Y`` (N, p), ``R`` (N, q) through the host build of the fixed-point C (cast to float32)."""
    return trace_from_run(artifact, fwfixed.run_host(artifact, Y, R))


def run_qemu(
    artifact: Artifact, Y: np.ndarray, R: np.ndarray, *, target: str | None = None, board: str | None = None
) -> Trace:
    """``Y``, ``R`` through the fixed-point image of ``target`` on ``board`` under QEMU (default cortex-m4)."""
    platform = resolve_cortex_m(target, board)
    run = fwfixed.run_qemu(artifact, Y, R, target=platform.target.name, board=platform.board.name)
    return trace_from_run(artifact, run)
