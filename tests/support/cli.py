"""``gainlink`` run in-process, its exit status and output captured."""

from __future__ import annotations

import io
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

from gainlink.cli import main

#: The installed console script (a process of its own: its logging configured as a user's is).
GAINLINK = Path(sys.executable).parent / "gainlink"


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


def gainlink_process(*argv: object, timeout: float = 120.0) -> CliResult:
    """Run the installed ``gainlink`` console script as its own process (its logging configured as a user's is)."""
    proc = subprocess.run(
        [str(GAINLINK), *map(str, argv)], capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL
    )
    return CliResult(code=proc.returncode, out=proc.stdout, err=proc.stderr)


#: A valid spec (the pendulum in compact form) that the bad-input tests bend one key at a time.
GOOD_SPEC = """\
name = "servo"
Ts = 0.01

[plant]
kind = "continuous"
A = [[0.0, 1.0], [0.0, -2.0]]
B = [[0.0], [4.0]]
C = [[1.0, 0.0]]

[controller]
method = "lqr"
Q_diag = [10.0, 0.1]
R_diag = [1.0]

[integral]
outputs = [0]
Q_diag = [1.0]

[observer]
method = "kalman"
W_diag = [1e-4, 1e-2]
V_diag = [1e-4]

[limits]
u_min = [-5.0]
u_max = [5.0]
"""


def assert_one_clear_line(res: CliResult, words: str) -> None:
    """Exit status 2 and exactly one line on stderr, ``gainlink: error: ...`` containing ``words``."""
    assert res.code == 2, (res.code, res.err)
    lines = [ln for ln in res.err.splitlines() if ln.strip()]
    assert len(lines) == 1, res.err
    assert lines[0].startswith("gainlink: error:"), lines[0]
    assert words in lines[0], lines[0]
    assert "Traceback" not in res.err
