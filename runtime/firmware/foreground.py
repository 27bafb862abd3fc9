"""A firmware process run in the foreground of a ``gainlink`` command: it never outlives the command.

Ctrl-C reaches both (the terminal signals the whole foreground process group); a SIGTERM sent to the command
alone (``kill PID``, a supervisor) is passed on to the process. The handler is in place before the process
starts: a SIGTERM that comes while it starts, or right after it printed that it is ready, is not lost, and the
command is not killed by it with the process left running.
"""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Sequence
from typing import Any


def run_in_foreground(argv: Sequence[str], **popen: Any) -> int:
    """Run ``argv`` to its end, passing on a SIGTERM this process receives meanwhile.

    Parameters
    ----------
    argv : sequence of str
        The command line.
    **popen
        Passed to :class:`subprocess.Popen` (e.g. ``stdin=subprocess.DEVNULL``).

    Returns
    -------
    int
        The process's exit status; 0 when it stopped because of a SIGTERM passed on to it or of Ctrl-C (it was
        asked to stop, and did; the command line then exits 130 for the Ctrl-C, the shell's convention).
    """
    started: list[subprocess.Popen] = []
    termed: list[int] = []

    def on_term(signum: int, frame: object) -> None:
        termed.append(signum)
        if started:
            started[0].send_signal(signal.SIGTERM)

    previous = signal.signal(signal.SIGTERM, on_term)
    proc: subprocess.Popen | None = None
    try:
        proc = subprocess.Popen(list(argv), **popen)
        started.append(proc)
        if termed:  # it came while the process was starting
            proc.send_signal(signal.SIGTERM)
        code = proc.wait()
        return 0 if termed and code == -signal.SIGTERM else code
    except KeyboardInterrupt:
        if proc is None:
            return 0
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=5)
        return 0 if code == -signal.SIGINT else code
    finally:
        signal.signal(signal.SIGTERM, previous)
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
