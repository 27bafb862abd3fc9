"""The ``gainlink`` command line.

Each module of this package that defines ``register(subparsers)`` contributes its subcommands;
a subcommand sets ``func(args) -> int``. User errors (any :class:`GainlinkError`, a missing file)
become one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import logging
import os
import pkgutil
import sys

# gainlink's matrices are small (tens of states): a BLAS thread pool does not speed them up, and its threads spin
# between calls, taking a core from the firmware, QEMU and the plant beside the loop (it doubled a design's CPU
# time on 2 cores). One thread, as Dask gives its workers, unless the user set it. Before numpy is imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from ..errors import GainlinkError
from ..version import __version__

log = logging.getLogger("gainlink")

EXIT_USAGE = 2


class _OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line and exit status 2."""

    def error(self, message: str) -> None:
        where = self.prog.removeprefix("gainlink").strip()
        self.exit(EXIT_USAGE, f"gainlink: error: {where + ': ' if where else ''}{message}\n")


@functools.cache
def build_parser() -> argparse.ArgumentParser:
    """Build the full parser from every command module of this package (``_name`` modules are helpers of the
    commands, imported by them when they run: not here, so building the parser stays cheap).

    Built once per process (13 ms; :func:`main` called in-process, as the tests do hundreds of times, reuses it:
    parsing leaves the parser unchanged)."""
    parser = _OneLineParser(prog="gainlink", description="State-space design to verified firmware.")
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
    """Entry point of the ``gainlink`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="gainlink: %(levelname)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args) or 0)
    except GainlinkError as exc:
        print(f"gainlink: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except FileNotFoundError as exc:
        print(f"gainlink: error: no such file: {exc.filename}", file=sys.stderr)
        return EXIT_USAGE
    except (IsADirectoryError, PermissionError) as exc:
        print(f"gainlink: error: cannot read {exc.filename}: {exc.strerror}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("gainlink: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
