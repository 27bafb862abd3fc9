"""A campaign worker's memory over many tasks: what a finished task freed is handed back, the caches are bounded.

Memory, not time: each test counts what the worker keeps (objects, cache entries) or, where what is kept is no object
at all (pages an allocator holds after the arrays on them were freed), measures it in a process started for the test
that runs nothing else, as a difference between two of its own states.
"""

from __future__ import annotations

import json
import subprocess
import sys

from support.paths import EXAMPLES

# In a fresh process: blocks of 20, 300 and 20 runs of the shipped pendulum campaign (one anti-windup mode, 2 s:
# 200 steps), its resident memory after each (statm, MB).
_BLOCKS = """
import gc, json, sys
from pathlib import Path
from gainlink.fileio import read_toml
from gainlink.hil.campaign import parse_campaign
from gainlink.hil.campaign.plan import plan_campaign
from gainlink.hil.campaign.worker import execute_block

path = Path(sys.argv[1])
data, _ = read_toml(path, what="campaign", error=ValueError)
data |= {"runs": 300, "spec": str((path.parent / data["spec"]).resolve())}
data["grid"][0]["values"] = ["none"]
data["scenario"]["duration"] = 2.0
plan = plan_campaign(parse_campaign(data))
runs = [(p.artifact_sha256, p.scenario, p.seed) for p in plan.runs]
ids = [p.id for p in plan.runs]
rss = []
for n in (20, 20, 300, 20):
    execute_block("sil", plan.artifacts, runs[:n], {}, ids=ids[:n], campaign="memory")
    gc.collect()
    with open("/proc/self/statm") as fh:
        rss.append(int(fh.read().split()[1]) * 4096 / 2**20)
print(json.dumps(rss))
"""


def test_a_worker_hands_back_what_a_large_block_freed():
    """After a 300-run block a worker holds about what it held after a 20-run block: the block's arrays and its
    Parquet file are freed at the task's end and the allocators (glibc's heap, Arrow's pool) give their pages back
    (:func:`~gainlink.hil.campaign.worker.hand_back_memory`). Without it the process kept 39 MB more after the large
    block (measured: 214 -> 253 MB; with it 206 -> 210), all of it freed memory (tracemalloc: 0.07 MB of Python
    objects alive after the task), so it is measured in a process of its own, as its growth from its own state
    after two small blocks, not counted in objects."""
    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    proc = subprocess.run([sys.executable, "-c", _BLOCKS, str(path)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    small, _, large, after = json.loads(proc.stdout.splitlines()[-1])
    assert large - small < 15.0, (small, large)
    assert after - small < 15.0, (small, after)


def _waiting_after(pause: float) -> bool:
    """:func:`~gainlink.hil.campaign.worker.next_task_waiting` in a task, after ``pause`` s: time for the scheduler to
    have handed this worker the task that follows, when there is one."""
    import time

    from gainlink.hil.campaign.worker import next_task_waiting

    time.sleep(pause)
    return next_task_waiting()


def test_a_worker_keeps_its_pages_for_its_next_block_and_hands_them_back_after_its_last():
    """A block's task hands its freed memory back only when no other task is ready on its worker: three tasks on a
    1-worker cluster (Dask gives a worker of one thread its next task while one runs) see a task waiting, a task
    waiting, then none (the last hands back). Outside a Dask worker (a test, the per-run path) a block always hands
    its memory back, as the test above measures."""
    from gainlink.hil.campaign.cluster import dask_client
    from gainlink.hil.campaign.worker import next_task_waiting

    assert next_task_waiting() is False
    with dask_client(workers=1) as client:
        client.wait_for_workers(1, timeout=60)
        futures = [client.submit(_waiting_after, 0.5, pure=False) for _ in range(3)]
        assert [f.result(timeout=60) for f in futures] == [True, True, False]


def test_a_workers_caches_keep_the_artifacts_it_used_last_not_every_one(pend):
    """A campaign that draws the design itself has an artifact per run. Over WORKER_CACHE + 6 runs of distinct
    artifacts the worker keeps WORKER_CACHE of them parsed (the last used, counted as live Artifact objects), not one
    per run; a run of a kept artifact finds it without parsing it again, and one dropped is parsed again and runs."""
    import gc

    from gainlink.hil.campaign import worker
    from gainlink.shipping.artifact import Artifact, canonical_json, seal

    base = json.loads(pend.read_text())
    docs = [canonical_json(seal(base | {"name": f"pendulum_{k}"})).encode() for k in range(worker.WORKER_CACHE + 6)]
    shas = [json.loads(doc)["sha256"] for doc in docs]
    assert len(set(shas)) == len(docs)
    scenario = {"duration": 0.05, "controller": "reference",
                "plant": {"kind": "cart_pendulum", "outputs": ["x", "theta"], "step": 0.005}}  # fmt: skip

    def alive() -> set[str]:
        gc.collect()
        return {o.sha256 for o in gc.get_objects() if isinstance(o, Artifact) and o.sha256 in shas}

    for doc in docs:
        assert worker.execute("sil", doc, scenario, 1)["status"] == "done"
    assert alive() == set(shas[-worker.WORKER_CACHE :])
    kept = worker.artifact_from_bytes(docs[-1])[0]
    assert worker.artifact_from_bytes(docs[-1])[0] is kept  # a hit: the same object, not parsed again
    assert worker.execute("sil", docs[0], scenario, 1)["status"] == "done"  # dropped: parsed again
    assert shas[0] in alive() and shas[-worker.WORKER_CACHE] not in alive()
