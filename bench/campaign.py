"""Campaigns on Dask: speed-up of 2 process workers over 1, overhead over a plain loop, worker memory.

Prints JSON. Everything is measured in the same run, against a baseline of the same run:

- ``sil``: 400 SIL runs of the pendulum (plant draws, 4 s each, with the twin) on the campaign's own
  LocalCluster (``gainlink.hil.campaign.cluster.dask_client``) of 1 process worker and of 2 (target:
  speed-up >= 1.8 on 2 cores);
- ``overhead``: the same 400 runs called one after the other in this process through the worker's own
  function (the plain loop: plan, then ``execute`` per run; no Dask, no files, no report), half before
  the 1-worker campaign and half after it (so a change of the machine's load hits both alike). Its CPU
  time per run is the baseline of ``overhead_ratio``: CPU of the whole campaign on 1 worker — this
  process (client, the LocalCluster's scheduler and nanny) and the worker process; plan, runs, result files
  and the merged report with its plots — per run / plain loop - 1 (target <= 0.10). Beside it:
  ``overhead_ratio_without_report`` (the report's CPU, a fixed cost per campaign, taken out), the wall
  ratio, and the number of Dask tasks the runs took;
- ``hil``: 40 lockstep HIL runs (firmware CAN process over udp_multicast, each in its own bus slot) on 1
  and on 2 workers;
- ``memory``: the single worker's resident memory after 40 runs and after 40 + 400 (target: flat).

Clusters are started before the timing (and warmed by a few runs that build the firmware), so the
times are those of the runs, the scheduling, the result files and the report. On a machine shared with
other work, read the ratios, not the seconds; ``load_average`` is the machine's before and after.

    .venv/bin/python bench/campaign.py          # ~5 min on 2 idle cores
"""

from __future__ import annotations

import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

# One BLAS/OpenMP thread, as Dask's nanny gives its workers (distributed.nanny.pre-spawn-environ): the plain
# loop runs here, and idle BLAS threads spinning after each small product would bill it for CPU the workers
# never spend. Set before numpy is imported.
for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

ROOT = Path(__file__).resolve().parents[1]
SIL_RUNS, HIL_RUNS, MEMORY_RUNS = 400, 40, 40


def sil_campaign(runs: int, seed: int) -> dict:
    """Pendulum SIL: cart and pendulum masses +-30 %, length +-10 %, 4 s from 0.5 m off the reference."""
    draws = [{"name": f"{p}_factor", "targets": [f"plant.parameters.{p}"], "distribution": "uniform",
              "low": lo, "high": hi, "apply": "scale"} for p, lo, hi in (("M", 0.7, 1.3), ("m", 0.7, 1.3),
                                                                          ("l", 0.9, 1.1))]
    return {"name": "bench_sil", "kind": "sil", "seed": seed, "runs": runs, "spec": str(ROOT / "examples/pendulum.toml"),
            "scenario": {"duration": 4.0, "initial_state": {"x": 0.5}, "noise": {"theta": 5e-4},
                         "plant": {"kind": "cart_pendulum", "outputs": ["x", "theta"], "step": 0.005,
                                   "parameters": {"M": 1.0, "m": 0.1, "l": 0.5}}},
            "draw": draws, "criteria": {"stable": True, "bounds": {"theta": [-0.7, 0.7]}}}


def hil_campaign(runs: int, seed: int) -> dict:
    """The SIL campaign's plants through the bridge: lockstep over CAN FD on udp_multicast, 2 s each."""
    c = sil_campaign(runs, seed)
    c.update(name="bench_hil", kind="hil")
    c["scenario"].update(duration=2.0, mode="lockstep", controller="firmware", step_timeout=2.0, peer_timeout=4.0,
                         transport={"interface": "udp_multicast", "channel": "239.74.164.1", "hop_limit": 0,
                                    "fd": True})
    return c


def _pid_cpu_s() -> tuple[int, float]:
    import psutil

    t = psutil.Process().cpu_times()
    return os.getpid(), t.user + t.system


def _cluster_cpu_s(client) -> float:
    """CPU seconds so far of the cluster's processes other than this one: the workers, and the nannies where
    they have a process of their own (a LocalCluster's nannies live in this process, whose CPU is counted
    by the caller: each process is counted once)."""
    cpu = dict(client.run(_pid_cpu_s).values()) | dict(client.run(_pid_cpu_s, nanny=True).values())
    cpu.pop(os.getpid(), None)
    return sum(cpu.values())


def timed_campaign(data: dict, client, out: Path) -> dict:
    """Wall time, and CPU time of the workers and nannies plus this process (client and the LocalCluster's
    scheduler); the CPU of this process after the last run was stored is the report's."""
    from gainlink.hil.campaign import run

    last = {}

    def progress(done: int, total: int, record: dict) -> None:
        if done == total:
            last["cpu"] = time.process_time()

    w0, c0, t0 = _cluster_cpu_s(client), time.process_time(), time.perf_counter()
    result = run(data, out=out, scheduler=client.scheduler.address, progress=progress)
    wall, c1, w1 = time.perf_counter() - t0, time.process_time(), _cluster_cpu_s(client)
    cpu = c1 - c0 + w1 - w0
    assert result.executed == result.total, "a bench campaign must start from an empty folder"
    n = result.total
    return {"runs": n, "wall_s": round(wall, 3), "per_run_ms": round(1e3 * wall / n, 2),
            "cpu_per_run_ms": round(1e3 * cpu / n, 2), "report_cpu_s": round(c1 - last["cpu"], 3),
            # Where the CPU went: the worker processes (the runs), and this process (client, scheduler and
            # nannies of a LocalCluster, result files, the report).
            "worker_cpu_per_run_ms": round(1e3 * (w1 - w0) / n, 2),
            "client_process_cpu_per_run_ms": round(1e3 * (c1 - c0) / n, 2),
            "passed": result.passed, "failed": result.failed, "errors": result.errors}


def plain_loop(data: dict, part: slice, *, plan_it: bool) -> dict:
    """The runs ``part`` through the worker's function in this process, one after the other (after a warm-up
    run); with ``plan_it`` the planning (the artifact's design) is timed too, as the campaign's is."""
    from gainlink.hil.campaign import parse_campaign
    from gainlink.hil.campaign.plan import plan_campaign
    from gainlink.hil.campaign.worker import execute

    plan = plan_campaign(parse_campaign(data))
    first = plan.runs[0]
    execute(plan.campaign.kind, plan.artifacts[first.artifact_sha256], first.scenario, first.seed, plan.blobs)
    t0, c0 = time.perf_counter(), time.process_time()
    if plan_it:
        plan = plan_campaign(parse_campaign(data))
    runs = plan.runs[part]
    for p in runs:
        execute(plan.campaign.kind, plan.artifacts[p.artifact_sha256], p.scenario, p.seed, plan.blobs)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"runs": len(runs), "wall_s": wall, "cpu_s": cpu}


def worker_rss_mb(client) -> float:
    import psutil

    return round(max(client.run(lambda: psutil.Process().memory_info().rss).values()) / 2**20, 1)


def main() -> int:
    logging.disable(logging.WARNING)
    from gainlink.hil.campaign.cluster import dask_client
    from gainlink.hil.campaign.runner import batch_sizes

    out = {"machine_cpus": len(os.sched_getaffinity(0)), "load_average_before": [round(v, 2) for v in os.getloadavg()]}
    half = SIL_RUNS // 2
    with tempfile.TemporaryDirectory(prefix="gainlink-bench-campaign-") as tmp:
        tmp = Path(tmp)
        plain = [plain_loop(sil_campaign(SIL_RUNS, seed=1), slice(0, half), plan_it=True)]
        res: dict[int, dict] = {}
        for n in (1, 2):
            with dask_client(workers=n) as client:
                timed_campaign(sil_campaign(2 * n, seed=99), client, tmp / f"warm_sil_{n}")
                timed_campaign(hil_campaign(2 * n, seed=99), client, tmp / f"warm_hil_{n}")
                r = {}
                if n == 1:
                    timed_campaign(sil_campaign(MEMORY_RUNS, seed=7), client, tmp / "memory40")
                    r["rss_after_40_mb"] = worker_rss_mb(client)
                r["sil"] = timed_campaign(sil_campaign(SIL_RUNS, seed=1), client, tmp / f"sil_{n}")
                r["sil"]["dask_tasks"] = len(batch_sizes("sil", SIL_RUNS, n))
                if n == 1:
                    r["rss_after_440_mb"] = worker_rss_mb(client)
                r["hil"] = timed_campaign(hil_campaign(HIL_RUNS, seed=1), client, tmp / f"hil_{n}")
                res[n] = r
            if n == 1:
                plain.append(plain_loop(sil_campaign(SIL_RUNS, seed=1), slice(half, None), plan_it=False))
    sil_speedup = res[1]["sil"]["wall_s"] / res[2]["sil"]["wall_s"]
    hil_speedup = res[1]["hil"]["wall_s"] / res[2]["hil"]["wall_s"]
    base_cpu = sum(p["cpu_s"] for p in plain) / SIL_RUNS
    base_wall = sum(p["wall_s"] for p in plain) / SIL_RUNS
    one = res[1]["sil"]
    # CPU time, not wall time, is the baseline: the machinery's cost per run whatever else the machine runs.
    overhead = one["cpu_per_run_ms"] / 1e3 / base_cpu - 1.0
    no_report = (one["cpu_per_run_ms"] / 1e3 - one["report_cpu_s"] / SIL_RUNS) / base_cpu - 1.0
    overhead_wall = one["per_run_ms"] / 1e3 / base_wall - 1.0
    memory_ratio = res[1]["rss_after_440_mb"] / res[1]["rss_after_40_mb"]
    out.update({
        "sil": {"runs": SIL_RUNS, "one_worker": res[1]["sil"], "two_workers": res[2]["sil"],
                "speedup_2_vs_1": round(sil_speedup, 3), "target_speedup": 1.8, "meets_target": sil_speedup >= 1.8},
        "hil": {"runs": HIL_RUNS, "one_worker": res[1]["hil"], "two_workers": res[2]["hil"],
                "speedup_2_vs_1": round(hil_speedup, 3)},
        "overhead": {"plain_loop": {"runs": SIL_RUNS, "per_run_ms": round(1e3 * base_wall, 2),
                                    "cpu_per_run_ms": round(1e3 * base_cpu, 2)},
                     "campaign_one_worker_per_run_ms": one["per_run_ms"],
                     "campaign_one_worker_cpu_per_run_ms": one["cpu_per_run_ms"],
                     "report_cpu_s": one["report_cpu_s"], "dask_tasks": one["dask_tasks"],
                     "overhead_ratio": round(overhead, 3), "overhead_ratio_without_report": round(no_report, 3),
                     "worker_vs_plain_loop": round(one["worker_cpu_per_run_ms"] / 1e3 / base_cpu - 1.0, 3),
                     "overhead_ratio_wall": round(overhead_wall, 3),
                     "target_overhead_ratio": 0.10, "meets_target": overhead <= 0.10},
        "memory": {"worker_rss_after_40_runs_mb": res[1]["rss_after_40_mb"],
                   "worker_rss_after_440_runs_mb": res[1]["rss_after_440_mb"],
                   "ratio": round(memory_ratio, 3), "flat": memory_ratio <= 1.10},
        "load_average_after": [round(v, 2) for v in os.getloadavg()],
    })
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
