"""The ``gainlink`` command line.

Each module of this package that defines ``register(subparsers)`` contributes its subcommands;
a subcommand sets ``func(args) -> int``. User errors (any :class:`GainlinkError`, a missing file)
become one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import logging
import os
import pkgutil
import re
import sys

# gainlink's matrices are small (tens of states): a BLAS thread pool does not speed them up, and its threads spin
# between calls, taking a core from the firmware, QEMU and the plant beside the loop (it doubled a design's CPU
# time on 2 cores). One thread, as Dask gives its workers, unless the user set it. Before numpy is imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from ..errors import GainlinkError, did_you_mean
from ..version import __version__

log = logging.getLogger("gainlink")

EXIT_USAGE = 2
EXIT_BROKEN_PIPE = 141

EXIT_STATUS_HELP = """\
exit status::

  0    done
  2    bad input: one line on stderr names the problem, nothing is written
  130  interrupted (Ctrl-C: the shell's 128 + SIGINT): one line on stderr, no traceback;
       the processes the command started are stopped (a campaign keeps its finished runs)
  other statuses are a command's own, in its help (e.g. campaign run 3, mavlink upload 3 and 4)"""


class _OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line and exit status 2."""

    def error(self, message: str) -> None:
        where = self.prog.removeprefix("gainlink").strip()
        self.exit(EXIT_USAGE, f"gainlink: error: {where + ': ' if where else ''}{_suggested(message)}\n")


_INVALID_CHOICE = re.compile(r"invalid choice: '(?P<name>[^']*)' \(choose from (?P<choices>.*)\)$")


def _suggested(message: str) -> str:
    """argparse's "invalid choice" message with the closest choice suggested (Python 3.11's argparse has none)."""
    m = _INVALID_CHOICE.search(message)
    if m is None:
        return message
    choices = [c.strip().strip("'") for c in m.group("choices").split(",")]
    hint = did_you_mean(m.group("name"), choices)
    return message[: m.end("name") + 1] + hint + message[m.end("name") + 1 :] if hint else message


@functools.cache
def build_parser() -> argparse.ArgumentParser:
    """Build the full parser from every command module of this package (``_name`` modules are helpers of the
    commands, imported by them when they run: not here, so building the parser stays cheap).

    Built once per process (13 ms; :func:`main` called in-process, as the tests do hundreds of times, reuses it:
    parsing leaves the parser unchanged)."""
    parser = _OneLineParser(
        prog="gainlink",
        description="State-space design to verified firmware.",
        epilog=EXIT_STATUS_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"gainlink {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug detail")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_OneLineParser)
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``gainlink`` console script; returns the exit status.

    ``argv`` None means this process's own command line: the process is the command, and after a Ctrl-C its exit
    is kept silent too (:func:`._interrupt.quiet_exit`). A caller passing ``argv`` keeps its process as it was.
    """
    from ._interrupt import EXIT_INTERRUPTED, InterruptWatch, quiet_exit

    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="gainlink: %(levelname)s: %(message)s",
        stream=sys.stderr,
    )
    with InterruptWatch(process=argv is None) as watch:
        try:
            status = int(args.func(args) or 0)
        except BrokenPipeError:  # stdout's reader left (| head): the shell's quiet end, 128 + SIGPIPE
            with contextlib.suppress(OSError, ValueError):  # not a file descriptor: a caller's own stream
                null = os.open(os.devnull, os.O_WRONLY)
                os.dup2(null, sys.stdout.fileno())  # Python's final flush of stdout would fail again: a traceback
                os.close(null)
            return EXIT_BROKEN_PIPE
        except Exception as exc:
            if not watch.seen:
                code = _user_error(exc)
                if code is None:
                    raise
                return code
            status = None  # what an interrupted clean-up raised: the interrupt's doing
        except KeyboardInterrupt:
            status = None
    if watch.seen or status is None:
        if status != EXIT_INTERRUPTED:  # a command that stopped on it has said what it kept
            print("gainlink: interrupted", file=sys.stderr)
        if argv is None:
            quiet_exit()
        return EXIT_INTERRUPTED
    return status


def _user_error(exc: Exception) -> int | None:
    """One line on stderr for a user error (any :class:`GainlinkError`, a file that cannot be read) and its exit
    status (2); None for anything else, a defect, which the caller raises again with its traceback."""
    if isinstance(exc, GainlinkError):
        print(f"gainlink: error: {exc}", file=sys.stderr)
    elif isinstance(exc, FileNotFoundError):
        print(f"gainlink: error: no such file: {exc.filename}", file=sys.stderr)
    elif isinstance(exc, (IsADirectoryError, PermissionError)):
        print(f"gainlink: error: cannot read {exc.filename}: {exc.strerror}", file=sys.stderr)
    else:
        return None
    return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
