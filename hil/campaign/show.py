"""Replay one run of a finished campaign by id and write its full HIL report.

A run is a pure function of (artifact, scenario, seed): ``plan.json`` and the artifacts and FMUs kept
in the campaign folder hold all three, so the run is executed again here, in this process, and
reported as ``gainlink hil run`` would (``report.json``, plots, ``summary.txt``).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from gainlink.errors import GainlinkError
from gainlink.fileio import read_user_file

from ..loop.bridge import RunResult
from ..loop.report import write_report
from .config import CampaignError
from .store import Store
from .worker import _scenario, artifact_from_bytes, run_point


def find_run(out: Path, run: str) -> dict:
    """The planned run ``run`` (an id, a unique id prefix, or an index) of the campaign in ``out``."""
    text = read_user_file(out / "plan.json", what="campaign plan", error=CampaignError)
    plan = json.loads(text)
    runs = plan["runs"]
    if run.isdigit() and int(run) < len(runs) and not any(r["id"].startswith(run) for r in runs):
        return runs[int(run)] | {"kind": plan["campaign"]["kind"]}
    hits = {r["id"]: r for r in runs if r["id"].startswith(run)}
    if len(hits) != 1:
        raise CampaignError(
            f"campaign {out}: {'no run' if not hits else 'several runs'} matching {run!r} "
            "(give a run id from campaign.csv, or its index)"
        )
    return next(iter(hits.values())) | {"kind": plan["campaign"]["kind"]}


def show_run(
    out: str | Path, run: str, *, report: str | Path | None = None, plots: bool = True
) -> tuple[RunResult, Path]:
    """Run campaign run ``run`` again and write its full report (default ``DIR/replay/<id>``).

    Returns the run's result and the report folder.
    """
    out = Path(out)
    point = find_run(out, run)
    if point.get("error"):
        raise CampaignError(f"run {point['id']} never ran: {point['error']}")
    store = Store(out)
    try:
        artifact, path = artifact_from_bytes(store.artifact_bytes(point["artifact_sha256"]))
    except OSError as exc:
        raise CampaignError(f"campaign {out}: the artifact of run {point['id']} is missing ({exc})") from None
    scenario = _scenario(
        point["scenario"], artifact_path=path, seed=point["seed"], blobs=store.blobs(), kind=point["kind"]
    )
    scenario = dataclasses.replace(scenario, name=f"{out.name} run {point['index']} ({point['id']})")
    try:
        result = run_point(point["kind"], artifact, scenario)
    except GainlinkError as exc:
        raise CampaignError(f"run {point['id']} failed again: {exc}") from None
    folder = Path(report) if report is not None else out / "replay" / point["id"]
    write_report(result, folder, artifact=artifact, with_plots=plots)
    return result, folder
