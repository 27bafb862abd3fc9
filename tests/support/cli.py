"""``gainlink`` run in-process (or any command as its own process), its exit status and output captured, and the
check every bad-input test makes of a refusal."""

from __future__ import annotations

import hashlib
import io
import subprocess
import sys
from collections.abc import Mapping, Sequence
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
    return run_process([GAINLINK, *argv], timeout=timeout)


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


def run_process(argv: Sequence[object], *, timeout: float = 120.0, **kw) -> CliResult:
    """Run ``argv`` as its own process (stdin from /dev/null); ``timeout`` is a hang guard."""
    proc = subprocess.run(
        [str(a) for a in argv], stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout, **kw
    )
    return CliResult(code=proc.returncode, out=proc.stdout, err=proc.stderr)


def _files(folders: Sequence[Path]) -> dict[str, str]:
    """Every file and folder under ``folders`` (hidden ones included), with a digest of each file's bytes."""
    state = {}
    for folder in folders:
        for path in [folder, *sorted(Path(folder).rglob("*"))] if Path(folder).exists() else []:
            digest = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "folder"
            state[str(path)] = digest
    return state


def assert_refused(
    argv: Sequence[object],
    phrase: str,
    *folders: Path,
    process: bool = False,
    prefix: str = "gainlink: error: ",
    env: Mapping[str, str] | None = None,
) -> CliResult:
    """Run ``gainlink argv`` in-process (``process=True``: the command line ``argv`` as its own process, in ``env``),
    given bad input, and check it was refused as the house rule says: exit status 2, stderr exactly one line,
    starting with ``prefix`` and containing ``phrase`` (so no traceback, no warning or progress line beside it), and
    nothing created, changed or removed under ``folders`` (hidden temporary files such as ``.NAME.*.tmp`` included).
    Returns the result."""
    before = _files(folders)
    res = run_process(argv, env=env) if process else run_cli(*argv)
    assert res.code == 2, f"exit status {res.code}, not 2: {res.err!r}"
    assert res.err.endswith("\n") and res.err.count("\n") == 1, f"stderr is not one line: {res.err!r}"
    assert res.err.startswith(prefix) and phrase in res.err, f"{res.err!r} does not say {phrase!r}"
    after = _files(folders)
    written = sorted(p for p in after if before.get(p) != after[p]) + sorted(p for p in before if p not in after)
    assert not written, f"the refused call wrote or removed {written}"
    return res
