"""``gainlink firmware run`` of a fixed-point artifact (``numeric = "q31" | "q15"``): the host build's loop executable
``gainlink_loop_host`` (firmware/ports/host/main.c), which runs the law the artifact certifies, its integer law.

Without ``--input`` stdin and stdout are the executable's: a line of samples then references (separated by spaces,
tabs or commas) in, one ``step`` line out, the integer law's record (:func:`gainlink.shipping.records.layout`);
``error ...`` for a line it cannot read, and exit status 2 at the end. With ``--input`` the samples are replayed
through it and written as the replay CSV ``gainlink replay`` writes for the artifact: after a ``# numeric=q31|q15``
line, the command words, estimate and integrators in real units (exact in double), the saturation and fault flags.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import DataError
from ..fileio import atomic_write_text
from ..laws import law_of
from ..laws.fixed.engines import trace_from_run
from ..laws.fixed.firmware import CLIPPED, FAULT, OVERFLOW, FixedRun
from ..proof.replay_io import read_samples
from ..shipping.artifact import Artifact
from ._host_exec import answer_samples, parse_records

EXECUTABLE = "gainlink_loop_host"


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
    """The executable's answer to ``count`` sample lines (after its banner) as a :class:`FixedRun`."""
    return FixedRun.from_records(parse_records(a, stdout, count=count, executable=EXECUTABLE), a.q)
