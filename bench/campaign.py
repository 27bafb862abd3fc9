"""Campaigns on Dask: speed-up of 2 process workers over 1, overhead over a plain loop, worker memory.

Prints JSON. Everything is measured in the same run, against a baseline of the same run:

- ``sil``: 400 SIL runs of the pendulum (plant draws, 4 s each) on a LocalCluster of 1 process worker and
  of 2 (target: speed-up >= 1.8 on 2 cores); the same 400 runs called one after the other in this
  process through the worker's own function (the plain loop: no Dask, no files, no report), whose CPU
  time per run is the baseline of ``overhead_ratio`` (CPU of the campaign on 1 worker — worker, client and
  scheduler — per run / plain loop - 1; target <= 0.10; the wall-time ratio is reported beside it);
- ``hil``: 40 lockstep HIL runs (firmware CAN process over udp_multicast, each in its own bus slot) on 1
  and on 2 workers;
- ``memory``: the single worker's resident memory after 40 runs and after 40 + 400 (target: flat).

Clusters are started before the timing (and warmed by a few runs that build the firmware), so the
times are those of the runs, the scheduling and the result files. On a machine shared with other work,
read the ratios, not the seconds.

    .venv/bin/python bench/campaign.py
"""

from __future__ import annotations

import json
import logging
import sys
import tempfile
import time
from pathlib import Path

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


def _workers_cpu_s(client) -> float:
    import psutil

    def cpu() -> float:
        t = psutil.Process().cpu_times()
        return t.user + t.system

    return sum(client.run(cpu).values())


def timed_campaign(data: dict, client, out: Path) -> dict:
    """Wall time, and CPU time of the workers plus this process (client and the LocalCluster's scheduler)."""
    from gainlink.hil.campaign import run

    w0, c0, t0 = _workers_cpu_s(client), time.process_time(), time.perf_counter()
    result = run(data, out=out, scheduler=client.scheduler.address)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0 + _workers_cpu_s(client) - w0
    assert result.executed == result.total, "a bench campaign must start from an empty folder"
    n = result.total
    return {"runs": n, "wall_s": round(wall, 3), "per_run_ms": round(1e3 * wall / n, 2),
            "cpu_per_run_ms": round(1e3 * cpu / n, 2), "passed": result.passed, "failed": result.failed,
            "errors": result.errors}


def plain_loop(data: dict) -> dict:
    """The same runs through the worker's function in this process, one after the other."""
    from gainlink.hil.campaign import parse_campaign
    from gainlink.hil.campaign.plan import plan_campaign
    from gainlink.hil.campaign.worker import execute

    plan = plan_campaign(parse_campaign(data))
    first = plan.runs[0]
    execute(plan.campaign.kind, plan.artifacts[first.artifact_sha256], first.scenario, first.seed, plan.blobs)  # warm
    t0, c0 = time.perf_counter(), time.process_time()
    for p in plan.runs:
        execute(plan.campaign.kind, plan.artifacts[p.artifact_sha256], p.scenario, p.seed, plan.blobs)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = len(plan.runs)
    return {"runs": n, "wall_s": round(wall, 3), "per_run_ms": round(1e3 * wall / n, 2),
            "cpu_per_run_ms": round(1e3 * cpu / n, 2)}


def worker_rss_mb(client) -> float:
    import psutil

    return round(max(client.run(lambda: psutil.Process().memory_info().rss).values()) / 2**20, 1)


def main() -> int:
    logging.disable(logging.WARNING)
    from distributed import Client, LocalCluster

    out = {"machine_cpus": None}
    import os

    out["machine_cpus"] = len(os.sched_getaffinity(0))
    with tempfile.TemporaryDirectory(prefix="gainlink-bench-campaign-") as tmp:
        tmp = Path(tmp)
        plain = plain_loop(sil_campaign(SIL_RUNS, seed=1))
        res: dict[int, dict] = {}
        for n in (1, 2):
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                              silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
                timed_campaign(sil_campaign(2 * n, seed=99), client, tmp / f"warm_sil_{n}")
                timed_campaign(hil_campaign(2 * n, seed=99), client, tmp / f"warm_hil_{n}")
                r = {}
                if n == 1:
                    timed_campaign(sil_campaign(MEMORY_RUNS, seed=7), client, tmp / "memory40")
                    r["rss_after_40_mb"] = worker_rss_mb(client)
                r["sil"] = timed_campaign(sil_campaign(SIL_RUNS, seed=1), client, tmp / f"sil_{n}")
                if n == 1:
                    r["rss_after_440_mb"] = worker_rss_mb(client)
                r["hil"] = timed_campaign(hil_campaign(HIL_RUNS, seed=1), client, tmp / f"hil_{n}")
                res[n] = r
    sil_speedup = res[1]["sil"]["wall_s"] / res[2]["sil"]["wall_s"]
    hil_speedup = res[1]["hil"]["wall_s"] / res[2]["hil"]["wall_s"]
    # CPU time, not wall time, is the baseline: the machinery's cost per run whatever else the machine runs.
    overhead = res[1]["sil"]["cpu_per_run_ms"] / plain["cpu_per_run_ms"] - 1.0
    overhead_wall = res[1]["sil"]["wall_s"] / plain["wall_s"] - 1.0
    memory_ratio = res[1]["rss_after_440_mb"] / res[1]["rss_after_40_mb"]
    out.update({
        "sil": {"runs": SIL_RUNS, "one_worker": res[1]["sil"], "two_workers": res[2]["sil"],
                "speedup_2_vs_1": round(sil_speedup, 3), "target_speedup": 1.8, "meets_target": sil_speedup >= 1.8},
        "hil": {"runs": HIL_RUNS, "one_worker": res[1]["hil"], "two_workers": res[2]["hil"],
                "speedup_2_vs_1": round(hil_speedup, 3)},
        "overhead": {"plain_loop": plain, "campaign_one_worker_per_run_ms": res[1]["sil"]["per_run_ms"],
                     "campaign_one_worker_cpu_per_run_ms": res[1]["sil"]["cpu_per_run_ms"],
                     "overhead_ratio": round(overhead, 3), "overhead_ratio_wall": round(overhead_wall, 3),
                     "target_overhead_ratio": 0.10, "meets_target": overhead <= 0.10},
        "memory": {"worker_rss_after_40_runs_mb": res[1]["rss_after_40_mb"],
                   "worker_rss_after_440_runs_mb": res[1]["rss_after_440_mb"],
                   "ratio": round(memory_ratio, 3), "flat": memory_ratio <= 1.10},
    })
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
