"""``gainlink`` run in-process, its exit status and output captured."""

from __future__ import annotations

import io
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass

from gainlink.cli import main


@dataclass(frozen=True)
class CliResult:
    """Exit status and captured output of one in-process ``gainlink`` call."""

    code: int
    out: str
    err: str


def run_cli(*argv: object) -> CliResult:
    """Run ``gainlink`` in-process; any uncaught exception fails the calling test."""
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse usage errors
            code = exc.code if isinstance(exc.code, int) else 1
    return CliResult(code=code, out=out.getvalue(), err=err.getvalue())
