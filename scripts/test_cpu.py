"""Sum the CPU seconds per test module (and list the costliest tests) from a ``GAINLINK_TEST_CPU`` file.

GAINLINK_TEST_CPU=/tmp/cpu.jsonl make test && .venv/bin/python scripts/test_cpu.py /tmp/cpu.jsonl
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path


def main() -> None:
    """Print the total, the modules by CPU and the ``--top`` costliest tests."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", type=Path)
    parser.add_argument("--top", type=int, default=25)
    args = parser.parse_args()
    records = [json.loads(line) for line in args.file.read_text().splitlines() if line.strip()]
    modules: Counter[str] = Counter()
    for rec in records:
        modules[rec["test"].split("::")[0]] += rec["cpu"]
    print(f"{sum(modules.values()):8.1f} s CPU in {len(records)} tests")
    for name, cpu in modules.most_common(args.top):
        print(f"{cpu:8.1f}  {name}")
    print()
    for rec in sorted(records, key=lambda r: -r["cpu"])[: args.top]:
        print(f"{rec['cpu']:8.1f}  {rec['test']}")


if __name__ == "__main__":
    main()
