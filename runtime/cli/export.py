"""``gainlink export ARTIFACT --out DIR``: the C gains header/source (and unrolled step) for the firmware."""

from __future__ import annotations

import argparse


def _export(args: argparse.Namespace) -> int:
    from gainlink.fileio import publish_files
    from gainlink.shipping.artifact import load
    from gainlink.shipping.export_c import render_export

    artifact = load(args.artifact)
    files = render_export(artifact)  # everything computed before anything is written
    written = publish_files(args.out, files)
    print(f"exported {artifact.name} sha256:{artifact.sha256[:12]}... -> " + ", ".join(str(p) for p in written))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export`` command."""
    p = subparsers.add_parser(
        "export",
        help="render the C gains (gl_gains.h, gl_gains.c, gl_step.h; scheduled: gl_sched_gains.c) from an artifact",
        description="Render the firmware's generated C from a gain artifact: dimensions as macros, the gain "
        "set as a const gl_gains_t, the fully unrolled step; a scheduled artifact: its per-point tables as a const "
        "gl_sched_tables_t. Same artifact, same bytes.",
    )
    p.add_argument("artifact", help="gains.json")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=_export)
