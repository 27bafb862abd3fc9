"""Ctrl-C on the command line: exit status 130 and one line, never a traceback.

A terminal's Ctrl-C sends SIGINT to every process of the foreground group, and Python turns it into a
``KeyboardInterrupt`` wherever the main thread happens to be. Three places printed tracebacks where the command's
own handling could not see them:

- a ``__del__`` or a callback the interrupt landed in (pyparsing's ``Forward.__del__`` while matplotlib imported
  it): Python reports the exception as "ignored" and carries on, so the command did not even stop;
- an exception that the interrupted clean-up raised in its place (Dask closing a cluster whose workers were
  still starting: ``AssertionError: Status.init``);
- the interpreter's exit after the command returned 130 (Dask's ``atexit`` closing that cluster again).

:class:`InterruptWatch` covers the first two while a command runs: it raises an interrupt a ``__del__`` swallowed
again in the main thread, and remembers that one came, so that whatever the command raises after it is the
interrupt's doing and ends with status 130. :func:`quiet_exit` covers the third, for the process that is the
command (not a caller of :func:`gainlink.cli.main` in its own process): Python's exit still runs every ``atexit``
handler and finaliser (Dask stops its cluster, temporary folders go), with nothing more on stderr, and a further
Ctrl-C ends the process at once (its workers follow, each watching its parent).
"""

from __future__ import annotations

import _thread
import logging
import os
import signal
import sys
import threading
import time
from types import FrameType, TracebackType
from typing import Any

EXIT_INTERRUPTED = 130  # 128 + SIGINT, the shell's status for a command a Ctrl-C stopped


class InterruptWatch:
    """For the length of a ``with`` block in the main thread: every Ctrl-C is remembered (:attr:`seen`), and one that
    a ``__del__`` or a callback swallowed is raised again in the main thread.

    A SIGINT that was ignored when the block began (a shell's background job) stays ignored; a handler other than
    Python's own is left alone. When the block ends the unraisable-exception hook is put back, and so is the SIGINT
    handler, unless ``process`` (the process is the command and is about to exit): then a Ctrl-C from there on ends
    it at once with status 130, which covers the interpreter's exit (Dask closing its cluster at ``atexit``).
    """

    def __init__(self, *, process: bool = False) -> None:
        self.seen = False
        self._process = process
        self._old_handler: Any = None
        self._old_hook: Any = None
        self._in_hook = False

    def __enter__(self) -> InterruptWatch:
        if threading.current_thread() is threading.main_thread():
            if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                self._old_handler = signal.signal(signal.SIGINT, self._on_sigint)
        self._old_hook = sys.unraisablehook
        sys.unraisablehook = self._on_unraisable
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._old_handler is not None:
            signal.signal(signal.SIGINT, _exit_now if self._process else self._old_handler)
        sys.unraisablehook = self._old_hook

    def _on_sigint(self, signum: int, frame: FrameType | None) -> None:
        self.seen = True
        raise KeyboardInterrupt

    def _on_unraisable(self, unraisable: Any) -> None:
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            self._old_hook(unraisable)
            return
        self.seen = True
        if self._old_handler is None:  # not our handler in place: it is only remembered
            return
        # Raised again once this hook has returned: a signal tripped in here would be handled at this hook's next
        # call instruction, inside it, and swallowed again. The main thread keeps the GIL from the flag's store to
        # the return (no eval-breaker check between them), so the helper's interrupt_main() comes after it.
        self._in_hook = True
        threading.Thread(target=self._interrupt_main_after_hook, name="gainlink-interrupt", daemon=True).start()
        self._in_hook = False

    def _interrupt_main_after_hook(self) -> None:
        while self._in_hook:
            time.sleep(0.0005)
        _thread.interrupt_main()


def _flush_stdio() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # closed, detached, or a write in progress that the signal interrupted
            pass


def _exit_now(signum: int, frame: FrameType | None) -> None:
    """A Ctrl-C once the command is over: what it wrote is flushed and the process ends with status 130 (its
    workers and the fork server follow, each watching its parent)."""
    _flush_stdio()
    os._exit(EXIT_INTERRUPTED)


def quiet_exit() -> None:
    """After an interrupt, make the rest of this process's life silent: what is written is flushed, then stderr goes
    to the null device, exceptions that ``atexit`` handlers and finalisers raise are dropped and logging stops.
    Only for the process that is the command."""
    _flush_stdio()
    sys.unraisablehook = lambda unraisable: None
    logging.disable(logging.CRITICAL)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    os.close(null)
