"""What work costs on this machine when its code and data were last touched a while ago, and what that costs a campaign
block's work outside its runs (the campaign benchmark's ``workers_outside_runs``).

On the virtual machines this project is measured on, the same work takes more CPU time when the memory it touches
(its data, and the code it runs) was not touched in the last tens of milliseconds, whatever the thread did meanwhile:
measured, not explained (the guest reports no steal time and few page faults; its hardware counters are not exposed).
A campaign worker's steps outside the runs (the block's file made and written, Dask's handling of the task) run once
a block, after ~0.5 s of the runs, so they always run in that state.

- ``probe``: a fixed piece of work (50 numpy sums over a 1.6 MB array, then ``json.dumps`` of 20,000 small dicts)
  timed at once after itself (``baseline``, in the same run) and after the thread spun on the clock for 0.05, 0.2 and
  0.5 s (busy, touching almost nothing): thread CPU, medians of :data:`REPEATS`, and the ratio to the baseline.
- ``block``: the shipped pendulum campaign's runs in blocks of the 10,000-run benchmark's size (10,002 runs in 6
  blocks of 1,667, each stepped in two lockstep parts) run in this process as a worker runs them (``execute_packed``),
  the block's file made (``encode_runs``) right after its runs (``encode_cold``: what a worker does) and at once again
  from the same runs (``encode_warm``); thread CPU a run, medians over :data:`BLOCKS` blocks after a first one;
  ``penalty_ms_a_block`` their difference; ``outside_runs_us_a_run`` the task's CPU outside the runs (the runs' own as
  the campaign measures it, around the runs; the second encode not counted; its memory kept between blocks, as a
  worker with blocks queued keeps it) and ``penalty_share_of_outside`` the penalty's part of it.
"""

from __future__ import annotations

import json
import os
import pickle
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import numpy as np
from campaign import BLOCK_DRAWS, shipped_pendulum  # bench/campaign.py: a script's folder is on its path

REPEATS = 5
PAUSES_S = (0.05, 0.2, 0.5)
BLOCKS = 8
WORKERS = 2  # the 10,000-run benchmark's cluster, whose block size the runner chooses (runner.batch_sizes)


def _spin(seconds: float) -> None:
    """Keep this thread busy for ``seconds`` on the clock alone."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def _probe_work() -> Callable[[], None]:
    array = np.random.default_rng(1).random(200_000)
    dicts = [{"a": float(i), "b": [1.0, 2.0, float(i)], "c": "x" * 10} for i in range(20_000)]

    def work() -> None:
        for _ in range(50):
            array.sum()
        json.dumps(dicts)

    return work


def probe() -> dict:
    """The probe's thread CPU at once after itself and after each pause (ms), and the ratios to the first."""
    work = _probe_work()
    out: dict = {}
    for label, pause in (("baseline", 0.0), *((f"after_{p}_s", p) for p in PAUSES_S)):
        times = []
        for _ in range(REPEATS):
            work()
            _spin(pause)
            t0 = time.thread_time()
            work()
            times.append(time.thread_time() - t0)
        out[f"{label}_ms"] = round(1e3 * statistics.median(times), 2)
    base = out["baseline_ms"]
    out["ratio_to_baseline"] = {k.removesuffix("_ms"): round(v / base, 2) for k, v in out.items() if k != "baseline_ms"}
    return out


def block() -> dict:
    """The shipped pendulum campaign's blocks run as a worker runs them, their files made cold and again warm."""
    import pyarrow.parquet as pq
    from gainlink.hil.campaign import parse_campaign
    from gainlink.hil.campaign import worker as wk
    from gainlink.hil.campaign.block_file import folder_key
    from gainlink.hil.campaign.plan import plan_campaign
    from gainlink.hil.campaign.runner import batch_sizes

    plan = plan_campaign(parse_campaign(shipped_pendulum(BLOCK_DRAWS)))
    runs = len(plan.runs.ids)
    size = batch_sizes("sil", runs, WORKERS)[0]
    if (1 + BLOCKS) * size > runs:  # the blocks' runs from more draws of the same campaign
        plan = plan_campaign(parse_campaign(shipped_pendulum(BLOCK_DRAWS * -(-(1 + BLOCKS) * size // runs))))
    artifacts = dict(plan.artifacts)
    cold: list[float] = []
    warm: list[float] = []
    encode = wk.encode_runs

    def encode_twice(ids: list[str], runs, *, campaign: str):
        t0 = time.thread_time()
        encode(ids, runs, campaign=campaign)
        t1 = time.thread_time()
        data = encode(ids, runs, campaign=campaign)
        cold.append(t1 - t0)
        warm.append(time.thread_time() - t1)
        return data

    outside = []
    # a worker with more blocks queued keeps its memory between them (worker.next_task_waiting)
    with (
        tempfile.TemporaryDirectory() as tmp,
        mock.patch.object(wk, "encode_runs", encode_twice),
        mock.patch.object(wk, "next_task_waiting", lambda: True),
    ):
        folder = Path(tmp)
        for b in range(1 + BLOCKS):
            at = np.arange(b * size, (b + 1) * size)
            ids = [i.decode() for i in plan.runs.ids[at].tolist()]
            packed = pickle.dumps((ids, plan.runs.task(at), np.zeros(size, bool)))
            t0 = time.thread_time()
            answer = wk.execute_packed("sil", artifacts, packed, {}, campaign="cold", folder=(tmp, folder_key(folder)))
            task = time.thread_time() - t0
            worker = pq.read_table(folder / answer["block"], columns=["worker"]).column("worker").combine_chunks()
            own = float(np.sum(worker.field("cpu_s").to_numpy()))
            outside.append(task - own - warm[-1])

    def per_run(seconds: list[float]) -> float:  # the first block apart (this process's first use of each part)
        return round(1e6 * statistics.median(seconds[1:]) / size, 1)

    penalty = statistics.median(c - w for c, w in zip(cold[1:], warm[1:]))
    return {
        "runs_a_block": size,
        "blocks": BLOCKS,
        "encode_cold_us_a_run": per_run(cold),
        "encode_warm_us_a_run": per_run(warm),
        "penalty_ms_a_block": round(1e3 * penalty, 2),
        "outside_runs_us_a_run": per_run(outside),
        "penalty_share_of_outside": round(penalty / statistics.median(outside[1:]), 3),
    }


def main() -> None:
    print(json.dumps({"probe": probe(), "block": block(), "load_average": round(os.getloadavg()[0], 2)}, indent=2))


if __name__ == "__main__":
    main()
