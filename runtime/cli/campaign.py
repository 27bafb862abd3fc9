"""``gainlink campaign run|show``: many SIL/HIL runs on Dask, and one of them replayed with its full report.

Exit status of ``run``: 0 every run has a result (pass or fail: see the summary); 2 the campaign file or an option
is wrong (nothing written); 3 some runs errored (the summary and ``failures.txt`` say why; the same command runs
them again, and only them); 130 interrupted (Ctrl-C: the cluster is stopped, every finished run kept, and one line
gives the command that resumes).
"""

from __future__ import annotations

import argparse
import json
import logging
import shlex
import sys
from pathlib import Path

from ._interrupt import EXIT_INTERRUPTED
from .hil import _progress_bar

log = logging.getLogger("gainlink")

EXIT_RUNS_ERRORED = 3


def _resume_command(args: argparse.Namespace) -> str:
    """The ``campaign run`` command line that continues this one (the same campaign, folder and cluster)."""
    argv = ["gainlink", "campaign", "run", args.campaign, "--out", args.out]
    for flag, value in (("--scheduler", args.scheduler), ("--workers", args.workers), ("--batch", args.batch)):
        if value is not None:
            argv += [flag, str(value)]
    return shlex.join(argv + (["--no-plots"] if args.no_plots else []))


def _run(args: argparse.Namespace) -> int:
    from gainlink.hil.campaign import CampaignInterrupted

    try:
        return _run_campaign(args)
    except CampaignInterrupted as stop:
        print(
            f"gainlink: interrupted: {stop.finished} of {stop.total} runs have a result in {stop.out} (kept); "
            f"resume with: {_resume_command(args)}",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED


def _run_campaign(args: argparse.Namespace) -> int:
    from gainlink.hil.campaign import load_campaign, run
    from gainlink.hil.campaign.cluster import quiet_dask_logs

    campaign = load_campaign(args.campaign)
    if not args.verbose:  # Dask's connection chatter is not the user's business
        quiet_dask_logs(logging.WARNING)
    with _progress_bar(not args.no_progress) as bar:
        callback = None
        if bar is None and not args.no_progress:  # not a terminal: a line per tenth of the campaign
            step = max(1, campaign.size // 10)

            def callback(done: int, total: int, record: dict) -> None:
                if done % step == 0 or done == total:
                    log.info("campaign %s: %d/%d runs done", campaign.name, done, total)

        if bar is not None:
            task = bar.add_task(f"campaign {campaign.name}", total=campaign.size)
            failed = [0]

            def callback(done: int, total: int, record: dict) -> None:
                failed[0] += record["status"] == "error"
                bar.update(
                    task,
                    completed=done,
                    total=total,
                    description=f"campaign {campaign.name}" + (f" ({failed[0]} errors)" if failed[0] else ""),
                )

        result = run(
            campaign,
            out=Path(args.out),
            scheduler=args.scheduler,
            workers=args.workers,
            progress=callback,
            batch=args.batch,
            plots=not args.no_plots,
        )
    sys.stdout.write(result.summary)
    if result.reused:
        sys.stdout.write(f"  resumed: {result.reused} runs had results, {result.executed} ran now\n")
    if result.errors:
        print(
            f"gainlink: error: {result.errors} of {result.total} runs errored (reasons in "
            f"{result.out / 'failures.txt'}); the same command runs them again, and only them, once the cause is fixed",
            file=sys.stderr,
        )
        return EXIT_RUNS_ERRORED
    return 0


def _show(args: argparse.Namespace) -> int:
    from gainlink.errors import GainlinkError
    from gainlink.hil.campaign import show_run, stored_run
    from gainlink.hil.loop.report import summary_text

    out = Path(args.dir)
    if args.record and args.run is None and args.index is None:
        raise GainlinkError("campaign show: --record prints one run: give --run ID or --index N")
    if args.run is None and args.index is None:
        path = out / "summary.txt"
        if not path.is_file():
            raise GainlinkError(f"{out} holds no campaign report (no summary.txt)")
        sys.stdout.write(path.read_text("utf-8"))
        return 0
    if args.record:
        if args.report is not None or args.no_plots:
            raise GainlinkError("campaign show: --record prints the stored run; --report and --no-plots are a replay's")
        sys.stdout.write(json.dumps(stored_run(out, args.run, index=args.index), indent=1, sort_keys=True) + "\n")
        return 0
    result, folder = show_run(out, args.run, index=args.index, report=args.report, plots=not args.no_plots)
    sys.stdout.write(summary_text(result, report_dir=folder))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``campaign`` to the gainlink CLI."""
    p = subparsers.add_parser("campaign", help="many SIL/HIL runs over uncertainty, grids and faults (Dask)")
    sub = p.add_subparsers(dest="campaign_command", metavar="CAMPAIGN_COMMAND")
    sub.required = True

    r = sub.add_parser("run", help="run a campaign (resumes: runs with a result in --out are not run again)")
    r.add_argument("campaign", help="campaign TOML (see examples/campaigns/)")
    r.add_argument("--out", required=True, help="campaign folder: results by run id, campaign.json/.csv, plots")
    r.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (default: a LocalCluster)")
    r.add_argument("--workers", type=int, help="LocalCluster process workers (default: one per CPU)")
    r.add_argument(
        "--batch",
        type=int,
        metavar="N",
        help="runs per Dask task (default: SIL up to 16, at least 4 tasks per worker thread; HIL 1)",
    )
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument(
        "--no-plots", action="store_true", help="no envelopes.png and scatter.png (about a second less per campaign)"
    )
    r.set_defaults(func=_run)

    s = sub.add_parser(
        "show", help="print a campaign's summary, or replay one run with its full HIL report (or print its record)"
    )
    s.add_argument("dir", help="campaign folder")
    which = s.add_mutually_exclusive_group()
    which.add_argument("--run", metavar="ID", help="replay the run with this id (or a start of it no other id shares)")
    which.add_argument("--index", type=int, metavar="N", help="replay the run at this index (its row in campaign.csv)")
    s.add_argument("--report", help="report folder of the replayed run (default DIR/replay/ID)")
    s.add_argument("--no-plots", action="store_true", help="report.json and summary.txt only")
    s.add_argument(
        "--record",
        action="store_true",
        help="print the run's stored record (inputs, metrics, measures) and its verdict as JSON, without a replay",
    )
    s.set_defaults(func=_show)
