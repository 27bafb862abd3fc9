"""What ``gainlink pil run`` prints: the JSON summary with ``--json``, else the one-screen text (``hil run``'s
kind, :mod:`gainlink.hil.loop.pil_report`), from the same dict ``pil.json`` holds."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def print_pil_summary(args: argparse.Namespace, summary: dict, *, artifact, json_text: str) -> int:
    """Print the run's summary as ``args`` ask; the exit status (0)."""
    from gainlink.hil.loop.pil_report import pil_summary_text

    if args.json:
        sys.stdout.write(json_text)
    else:
        sys.stdout.write(pil_summary_text(summary, artifact=artifact, out_dir=Path(args.out) if args.out else None))
    return 0
