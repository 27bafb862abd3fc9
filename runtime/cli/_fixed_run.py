"""``gainlink firmware run`` of a fixed-point artifact (``numeric = "q31" | "q15"``): the host build's integer loop
executable ``gainlink_fixed_loop_host`` (firmware/ports/host/fixed_main.c), the law the artifact certifies, rather
than the float32 loop executable of the same export.

Without ``--input`` stdin and stdout are the executable's: the float loop's input lines (samples then references,
separated by spaces, tabs or commas; ``reset``), each answered by one line (``step FLAGS SAT CLIP OVERFLOW U.. V..
XH.. Z..``, integers; ``reset 0``; ``error ...`` for a line it cannot read, and exit status 2 at the end). With
``--input`` the samples are replayed through it and written as the replay CSV ``gainlink replay`` writes for the
artifact: after a ``# numeric=q31|q15`` line, the command words, estimate and integrators in real units (exact in
double), the saturation and fault flags.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ..engines.fixed import trace_from_run
from ..errors import DataError, FirmwareError
from ..fileio import atomic_write_text
from ..firmware.fixed import CLIPPED, FAULT, OVERFLOW, FixedRun
from ..laws import law_of
from ..proof.fixed_format import real
from ..proof.replay_io import read_samples
from ..shipping.artifact import Artifact
from ._host_exec import answer_samples

EXECUTABLE = "gainlink_fixed_loop_host"


def run_fixed_host(artifact: Artifact, build_dir: Path, *, input_path: Path | None, output_path: Path | None) -> int:
    """Run the integer loop executable of the host build in ``build_dir``: on stdin/stdout, or replaying the CSV
    ``input_path`` into ``output_path`` (stdout when ``None``). Returns the exit status."""
    exe = Path(build_dir) / EXECUTABLE
    if input_path is None:
        from ..firmware.foreground import run_in_foreground

        return run_in_foreground([str(exe)])
    return _replay(artifact, exe, input_path, output_path)


def _replay(a: Artifact, exe: Path, input_path: Path, output_path: Path | None) -> int:
    samples = read_samples(input_path, a)
    stdout, count = answer_samples(exe, samples.Y, samples.R)
    run = parse_steps(a, stdout, count=count)
    text = law_of(a).trace_text(a, trace_from_run(a, run), samples.t, engine="native")
    if output_path is None:
        sys.stdout.write(text)
        return 0
    if output_path.is_dir():
        raise DataError(f"output {output_path} is a directory")
    atomic_write_text(output_path, text)
    print(
        f"ran {count} samples through {exe.name} ({law_of(a).label} integer law): "
        f"{int((run.sat != 0).sum())} saturated, {int(((run.flags & FAULT) != 0).sum())} refused, "
        f"{int(((run.flags & CLIPPED) != 0).sum())} clipped, {int(((run.flags & OVERFLOW) != 0).sum())} overflowed"
    )
    return 0


def parse_steps(a: Artifact, stdout: str, *, count: int) -> FixedRun:
    """The executable's answer to ``count`` sample lines (after its banner) as a :class:`FixedRun`; the float
    commands are the command words' values, as the C computes them."""
    out = stdout.splitlines()
    if not out or not out[0].startswith(f"gainlink-fixed {a.name} sha256:{a.sha256}"):
        raise FirmwareError(f"{EXECUTABLE} was not built for artifact {a.name} (banner {out[0] if out else ''!r})")
    steps = out[1:]
    width = 4 + 2 * a.m + a.n + a.q
    bad = next((k for k, ln in enumerate(steps) if not ln.startswith("step ") or len(ln.split()) != 1 + width), None)
    if bad is not None or len(steps) != count:
        where = f"line {bad + 1} is {steps[bad][:60]!r}" if bad is not None else f"{len(steps)} lines"
        raise FirmwareError(f"{EXECUTABLE} answered {count} samples unexpectedly: {where}")
    words = np.array([[int(v) for v in ln.split()[1:]] for ln in steps], dtype=np.int64).reshape(count, width)
    m, n = a.m, a.n
    U = words[:, 4 : 4 + m]
    fu = np.array(a.checks["fixed_point"]["formats"]["u"])
    masks = words[:, :4].astype(np.uint32)
    return FixedRun(
        U=U,
        V=words[:, 4 + m : 4 + 2 * m],
        XH=words[:, 4 + 2 * m : 4 + 2 * m + n],
        Z=words[:, 4 + 2 * m + n :],
        u=real(U, fu).astype(np.float32),
        flags=masks[:, 0],
        sat=masks[:, 1],
        clip=masks[:, 2],
        overflow=masks[:, 3],
    )
