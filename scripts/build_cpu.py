"""Where the firmware builds of a run went: Ninja's edge times per kind and per source file, and ccache's hits.

make test && .venv/bin/python scripts/build_cpu.py            # the build trees under .cache/ of this checkout

Ninja logs each edge's wall time (``.ninja_log`` in every build tree). In a parallel test run two builds share the
cores, so the times are about twice their CPU; compare runs with each other, not with CPU seconds. A compile edge
that ccache answered takes ~10 ms, so a source with many long edges is one that compiles again per structure.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def edge_kind(output: str) -> str:
    """compile, archive, shared, link or other, from an edge's output path."""
    if output.endswith((".o", ".obj")):
        return "compile"
    if output.endswith(".a"):
        return "archive"
    if output.endswith(".so"):
        return "shared"
    if output.endswith(".elf") or "." not in os.path.basename(output):
        return "link"
    return "other"


def source_of(output: str) -> str:
    """The source an object is compiled from, the same for every build tree (``gen/`` for generated ones)."""
    src = re.sub(r"\.(o|obj)$", "", re.sub(r".*\.dir/", "", output))
    return re.sub(r"^.*gen/", "gen/", src)


def read_logs(cache: Path) -> list[tuple[str, float]]:
    """(output, seconds) of every edge in the ``.ninja_log`` files under ``cache`` (each edge's last run)."""
    edges = []
    for log in sorted(cache.glob("**/.ninja_log")):
        last: dict[str, float] = {}
        for line in log.read_text().splitlines():
            fields = line.split("\t")
            if line.startswith("#") or len(fields) < 4:
                continue
            last[fields[3]] = (int(fields[1]) - int(fields[0])) / 1000.0
        edges.extend(last.items())
    return edges


def main() -> None:
    """Print the edges by kind, the ``--top`` sources by compile time, and ccache's statistics."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, default=ROOT / ".cache", help="the folder holding the build trees")
    parser.add_argument("--top", type=int, default=20)
    args = parser.parse_args()
    if not args.cache.is_dir():
        parser.error(f"{args.cache} is not a folder (the build trees are under the checkout's .cache/)")
    edges = read_logs(args.cache)
    trees = len(list(args.cache.glob("**/.ninja_log")))
    kinds: Counter[str] = Counter()
    counts: Counter[str] = Counter()
    for output, seconds in edges:
        kinds[edge_kind(output)] += seconds
        counts[edge_kind(output)] += 1
    print(f"{sum(kinds.values()):8.1f} s in {len(edges)} edges of {trees} build trees")
    for kind, seconds in kinds.most_common():
        print(f"{seconds:8.1f}  {counts[kind]:5d}  {kind}")
    sources: Counter[str] = Counter()
    compiles: Counter[str] = Counter()
    for output, seconds in edges:
        if edge_kind(output) == "compile":
            sources[source_of(output)] += seconds
            compiles[source_of(output)] += 1
    print()
    for src, seconds in sources.most_common(args.top):
        print(f"{seconds:8.1f}  {compiles[src]:5d}  {src}")
    ccache = shutil.which("ccache")
    if ccache and (args.cache / "ccache").is_dir():
        env = dict(os.environ, CCACHE_DIR=str(args.cache / "ccache"))
        print()
        print(subprocess.run([ccache, "-s"], env=env, capture_output=True, text=True).stdout.rstrip())


if __name__ == "__main__":
    main()
