"""Run a campaign: plan it, submit the runs without a result to Dask, store each as it completes, merge.

Artifacts and FMUs go to the cluster once each (as tasks returning them, keyed by sha256), and every run is a task
``execute(kind, artifact, scenario, seed, fmus)`` whose key is its run id. Results come back through
``as_completed`` and are written one by one, so whatever finished before an interruption is kept.
A task that raised is retried once by Dask (``retries=1``); a run still failing, or whose workers died
under it (``KilledWorker``), is recorded as an error with the reason.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from .cluster import dask_client
from .config import Campaign, load_campaign, parse_campaign
from .plan import CampaignPlan, RunPoint, describe_axes, plan_campaign
from .report import merge
from .store import Store
from .worker import execute

log = logging.getLogger(__name__)

Progress = Callable[[int, int, dict], None]


@dataclass(frozen=True)
class CampaignResult:
    """A finished campaign: where its report is, its runs (one row each) and the counts.

    ``reused`` runs had a result before this call (a resumed campaign); ``executed`` ran now.
    """

    out: Path
    rows: tuple[dict, ...]
    passed: int
    failed: int
    errors: int
    reused: int
    executed: int
    summary: str

    @property
    def total(self) -> int:
        """Every run of the campaign."""
        return len(self.rows)


def as_campaign(campaign: Campaign | str | Path | Mapping) -> Campaign:
    """A :class:`Campaign` from a parsed one, a TOML file path, or a mapping."""
    if isinstance(campaign, Campaign):
        return campaign
    if isinstance(campaign, (str, Path)):
        return load_campaign(campaign)
    return parse_campaign(campaign)


def plan_doc(plan: CampaignPlan) -> dict:
    """``plan.json``: the campaign and every run's inputs."""
    c = plan.campaign
    return {"campaign": {"name": c.name, "kind": c.kind, "seed": c.seed, "runs_per_point": c.runs,
                         "spec": str(c.spec_path) if c.spec_path else None,
                         "artifact": str(c.artifact_path) if c.artifact_path else None,
                         "axes": describe_axes(c), "description": c.description},
            "runs": [{"index": r.index, "id": r.id, "grid_index": r.grid_index, "draw": r.draw, "values": r.values,
                      "seed": r.seed, "artifact_sha256": r.artifact_sha256, "scenario": r.scenario,
                      "error": r.error} for r in plan.runs]}


def run(campaign: Campaign | str | Path | Mapping, *, out: str | Path, scheduler: str | None = None,
        workers: int | None = None, progress: Progress | None = None) -> CampaignResult:
    """Run every run of a campaign that has no result in ``out`` yet, then write the merged report.

    Parameters
    ----------
    campaign : Campaign, path or mapping
        The campaign (a TOML file, or its content as a dict).
    out : path
        The campaign folder: results by run id, ``campaign.json``, ``campaign.csv``, plots, summary.
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:8786``); default: a LocalCluster on this machine.
    workers : int, optional
        LocalCluster process workers (default: one per CPU).
    progress : callable, optional
        ``progress(done, total, record)`` after each run is stored.

    Returns
    -------
    CampaignResult

    Examples
    --------
    >>> import gainlink.hil.campaign as campaign
    >>> result = campaign.run("examples/campaigns/pendulum_mass_uncertainty.toml", out="out/c")  # doctest: +SKIP
    >>> result.passed / result.total                                                             # doctest: +SKIP
    """
    campaign = as_campaign(campaign)
    plan = plan_campaign(campaign)
    store = Store(out)
    store.prepare(plan, plan_doc=plan_doc(plan))
    todo: dict[str, RunPoint] = {}
    reused = 0
    for point in plan.runs:
        if store.has(point.id) or point.id in todo:
            reused += store.has(point.id)
            continue
        if point.error is not None:
            store.put(point, kind=campaign.kind, result={"status": "error", "reason": point.error})
            continue
        todo[point.id] = point
    total = len({p.id for p in plan.runs})
    done = total - len(todo)
    if todo:
        with dask_client(scheduler=scheduler, workers=workers) as client:
            _submit_and_store(client, plan, todo, store, done=done, total=total, progress=progress)
    summary, rows = merge(plan, store)
    counts = {s: sum(1 for r in rows if r["status"] == s) for s in ("pass", "fail", "error")}
    return CampaignResult(out=store.out, rows=tuple(rows), passed=counts["pass"], failed=counts["fail"],
                          errors=counts["error"], reused=reused, executed=len(todo), summary=summary)


def _data(value: bytes) -> bytes:
    """A campaign input (artifact JSON, FMU archive) as the result of a task."""
    return value


def _submit_and_store(client: Any, plan: CampaignPlan, todo: dict[str, RunPoint], store: Store, *, done: int,
                      total: int, progress: Progress | None) -> None:
    from asyncio import CancelledError

    from distributed import as_completed

    kind = plan.campaign.kind
    # FMU archives go to the cluster once each, as tasks returning them (not scattered data): a task's result
    # lost with its worker is computed again from the graph, scattered data would be gone for good. Artifacts
    # (a few kB) travel inside each run's task: a run with no dependency goes to whichever worker is free,
    # instead of queueing on the worker that happens to hold the artifact.
    blobs = {sha: client.submit(_data, data, key=f"gainlink-fmu-{sha}") for sha, data in plan.blobs.items()}
    futures = {}
    for point in todo.values():
        needed = {s: f for s, f in blobs.items() if s in str(point.scenario.get("plant", {}).get("path", ""))}
        fut = client.submit(execute, kind, plan.artifacts[point.artifact_sha256], point.scenario, point.seed, needed,
                            key=f"gainlink-run-{point.id}", retries=1, pure=False)
        futures[fut] = point
    for fut in as_completed(list(futures)):
        point = futures.pop(fut)
        try:
            result = fut.result()
        except (Exception, CancelledError) as exc:  # retried once already; KilledWorker: its workers died
            result = {"status": "error", "reason": f"{type(exc).__name__}: {exc}"}
        record = store.put(point, kind=kind, result=result)
        fut.release()
        done += 1
        if record["status"] == "error":
            log.warning("run %s (%d) failed: %s", point.id, point.index, record["reason"])
        if progress is not None:
            progress(done, total, record)
