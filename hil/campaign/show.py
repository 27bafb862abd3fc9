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


def find_run(out: Path, run: str | None = None, *, index: int | None = None) -> dict:
    """The planned run of the campaign in ``out`` whose id starts with ``run``, or the one at ``index``.

    Exactly one of the two. ``run`` is always the start of an id, even when it is all digits (ids are hex:
    a number can be both an id prefix and an index, so the two are never guessed from one string).
    """
    if (run is None) == (index is None):
        raise CampaignError("campaign show: give a run id (or its unique start) or an index, not both or neither")
    text = read_user_file(out / "plan.json", what="campaign plan", error=CampaignError)
    plan = json.loads(text)
    runs, kind = plan["runs"], plan["campaign"]["kind"]
    if index is not None:
        if not 0 <= index < len(runs):
            raise CampaignError(f"campaign {out} has {len(runs)} runs (index 0 to {len(runs) - 1}), not {index}")
        return runs[index] | {"kind": kind}
    hits = {r["id"]: r for r in runs if r["id"].startswith(run)}
    if len(hits) != 1:
        hint = "give more of the id"
        if not hits:
            hint = "ids are in campaign.csv"
            if run.isdigit() and int(run) < len(runs):
                hint = f"for the run at index {int(run)}, give --index {int(run)}"
        raise CampaignError(
            f"campaign {out}: {'no run id' if not hits else f'{len(hits)} run ids'} matching {run!r} ({hint})"
        )
    return next(iter(hits.values())) | {"kind": kind}


def show_run(
    out: str | Path,
    run: str | None = None,
    *,
    index: int | None = None,
    report: str | Path | None = None,
    plots: bool = True,
) -> tuple[RunResult, Path]:
    """Run a campaign's run again and write its full report (default ``DIR/replay/<id>``).

    Parameters
    ----------
    out : path
        The campaign folder.
    run : str, optional
        The run's id, or a start of it that no other id shares.
    index : int, optional
        The run's index instead (its row in ``campaign.csv``).
    report : path, optional
        The report folder.
    plots : bool
        Write the plots too.

    Returns
    -------
    tuple of (RunResult, Path)
        The run's result and the report folder.
    """
    out = Path(out)
    point = find_run(out, run, index=index)
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
    write_report(result, folder, with_plots=plots)
    return result, folder
