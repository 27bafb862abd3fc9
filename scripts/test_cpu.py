"""Sum the CPU seconds per test module (and list the costliest tests) from a ``GAINLINK_TEST_CPU`` file.

GAINLINK_TEST_CPU=/tmp/cpu.jsonl make test && .venv/bin/python scripts/test_cpu.py /tmp/cpu.jsonl

``--timeline S`` lists instead, per xdist worker, when it finished and what it ran in the last S seconds of the
run (each test's start from the run's first, its wall and CPU seconds): the critical path.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter, defaultdict
from pathlib import Path


def _totals(records: list[dict], top: int) -> None:
    modules: Counter[str] = Counter()
    for rec in records:
        modules[rec["test"].split("::")[0]] += rec["cpu"]
    print(f"{sum(modules.values()):8.1f} s CPU in {len(records)} tests")
    for name, cpu in modules.most_common(top):
        print(f"{cpu:8.1f}  {name}")
    print()
    for rec in sorted(records, key=lambda r: -r["cpu"])[:top]:
        print(f"{rec['cpu']:8.1f}  {rec['test']}")


def _timeline(records: list[dict], last: float) -> None:
    timed = [r for r in records if "start" in r]
    if not timed:
        raise SystemExit("test_cpu: the file has no start times (recorded by an older conftest)")
    t0 = min(r["start"] for r in timed)
    end = max(r["start"] + r["wall"] for r in timed)
    by_worker: dict[str, list[dict]] = defaultdict(list)
    for rec in timed:
        by_worker[rec["worker"]].append(rec)
    print(f"run: {end - t0:.1f} s from the first test's start to the last one's end")
    for worker, recs in sorted(by_worker.items()):
        done = max(r["start"] + r["wall"] for r in recs) - t0
        busy = sum(r["wall"] for r in recs)
        print(f"\n{worker}: {len(recs)} tests, done at {done:.1f} s, {busy:.1f} s in tests, "
              f"{sum(r['cpu'] for r in recs):.1f} CPU-s")  # fmt: skip
        for rec in sorted(recs, key=lambda r: r["start"]):
            if rec["start"] + rec["wall"] - t0 >= end - t0 - last:
                print(f"  {rec['start'] - t0:7.1f} {rec['wall']:6.1f} {rec['cpu']:6.1f}  {rec['test']}")


def main() -> None:
    """Print the total, the modules by CPU and the ``--top`` costliest tests, or the ``--timeline``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", type=Path)
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--timeline", type=float, metavar="S", help="each worker's tests in the run's last S seconds")
    args = parser.parse_args()
    records = [json.loads(line) for line in args.file.read_text().splitlines() if line.strip()]
    if args.timeline is not None:
        _timeline(records, args.timeline)
    else:
        _totals(records, args.top)


if __name__ == "__main__":
    main()
