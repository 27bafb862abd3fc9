"""A run's resources closed whole when a Ctrl-C comes while they close.

Python raises a ``KeyboardInterrupt`` at the next point where its interpreter checks for signals. In an
:class:`~contextlib.ExitStack`'s unwinding that is often the entry of the next callback, which then never runs:
a HIL run interrupted just after its loop ended dropped its CAN link's buses unclosed, and python-can's finaliser
logged "UdpMulticastBus was not properly shut down" above the command's one line (seen in fresh-clone suites; traced
on a loaded machine: of 32 interrupted runs, 9 took the interrupt inside the stack's unwinding).
"""

from __future__ import annotations

import signal
import threading
from contextlib import ExitStack
from types import FrameType
from typing import Any


class ClosingStack(ExitStack):
    """An :class:`~contextlib.ExitStack` whose callbacks all run when a Ctrl-C comes while they do: from
    :meth:`closing` (or its own exit, whichever is first) a SIGINT is held, and raised through the handler that was
    in place (Python's, the CLI's) once the last callback has run. Before that a Ctrl-C is raised as usual (it stops
    the run). Only in the main thread, under a handler Python can call; elsewhere an ExitStack as any other."""

    def __enter__(self) -> ClosingStack:
        self._previous: Any = None
        self._held: list[FrameType | None] = []
        self._closing = False
        if threading.current_thread() is threading.main_thread() and callable(signal.getsignal(signal.SIGINT)):
            self._previous = signal.signal(signal.SIGINT, self._on_sigint)
        return super().__enter__()

    def closing(self) -> None:
        """From here on the stack's resources close: a Ctrl-C waits for them (say it as the block's last step; an
        exception out of the block says it on its way out)."""
        self._closing = True

    def __exit__(self, *exc: Any) -> bool:
        self._closing = True
        try:
            return super().__exit__(*exc)
        finally:
            if self._previous is not None:
                signal.signal(signal.SIGINT, self._previous)
                if self._held:
                    self._previous(signal.SIGINT, self._held[-1])

    def _on_sigint(self, signum: int, frame: FrameType | None) -> None:
        if self._closing:
            self._held.append(frame)
        else:
            self._previous(signum, frame)
