"""Replay one run of a finished campaign by id and write its full HIL report.

A run is a pure function of (artifact, scenario, seed): its record in the campaign folder's store (``inputs``) and
the artifacts and FMUs kept beside it hold all three (``plan.json`` names the run at each index), so the run is
executed again here, in this process, and reported as ``gainlink hil run`` would (``report.json``, plots,
``summary.txt``). A run with no record yet (a campaign interrupted before it) is run by resuming the campaign.
:func:`stored_run` gives a run's stored record with its verdict as the last merge judged it, without running it.
"""

from __future__ import annotations

import csv
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
    try:
        ids = json.loads(text)["run_ids"]
    except (ValueError, KeyError, TypeError):
        raise CampaignError(f"campaign: {out / 'plan.json'} is not a campaign plan this gainlink can read") from None
    if index is not None:
        if not 0 <= index < len(ids):
            raise CampaignError(f"campaign {out} has {len(ids)} runs (index 0 to {len(ids) - 1}), not {index}")
        return _stored_run(out, ids[index], index)
    hits = {i: k for k, i in reversed(list(enumerate(ids))) if i.startswith(run)}  # an id's first index
    if len(hits) != 1:
        hint = "give more of the id"
        if not hits:
            hint = "ids are in campaign.csv"
            if run.isdigit() and int(run) < len(ids):
                hint = f"for the run at index {int(run)}, give --index {int(run)}"
        raise CampaignError(
            f"campaign {out}: {'no run id' if not hits else f'{len(hits)} run ids'} matching {run!r} ({hint})"
        )
    run_id, at = next(iter(hits.items()))
    return _stored_run(out, run_id, at)


def _stored_run(out: Path, run_id: str, index: int) -> dict:
    """The inputs of run ``run_id`` (at ``index``) as its record in the store holds them."""
    try:
        record = Store(out).record(run_id)
    except KeyError:
        raise CampaignError(
            f"campaign {out}: run {run_id} has no record yet: run the campaign again to run it"
        ) from None
    inputs = record["inputs"]
    never = record.get("reason") if record["status"] == "error" and inputs["artifact_sha256"] is None else None
    return {"id": run_id, "index": index, **inputs, "error": never}


def stored_run(out: str | Path, run: str | None = None, *, index: int | None = None) -> dict:
    """A run of the campaign in ``out`` as its folder holds it, by id (or a start of it no other id shares) or by
    index, without running it: ``index``, ``id``, its ``verdict`` as the last merge wrote it in ``campaign.csv``
    (``status``, and ``reasons`` as the CSV's one text, joined by ``"; "``; ``None`` before a merge) and its whole
    ``record`` (inputs, metrics, measures, worker; an error's reason)."""
    out = Path(out)
    point = find_run(out, run, index=index)
    return {"index": point["index"], "id": point["id"], "verdict": _verdict(out, point["index"], point["id"]),
            "record": Store(out).record(point["id"])}  # fmt: skip


def _verdict(out: Path, index: int, run_id: str) -> dict | None:
    """Run ``run_id``'s (at ``index``) status and reasons in the folder's ``campaign.csv``, None without one."""
    path = out / "campaign.csv"
    if not path.is_file():
        return None
    with path.open(newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            if row.get("index") == str(index) and row.get("id") == run_id:
                return {"status": row["status"], "reasons": row["reasons"]}  # one text: a reason may hold "; "
    return None


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
