"""Long libFuzzer runs of every firmware harness: executions, coverage and crashes, as JSON.

Each harness starts from the seed corpus made from valid traffic for the pendulum example (the baseline:
libFuzzer's coverage of the seeds alone, measured in the same run; `cov_vs_seeds` is the ratio) and runs
until `--runs` executions (default 10 million; the target is that many with 0 crashes). The corpus and
any crash reproducers are kept in out/fuzz/HARNESS/. Runs at nice 10: the machine is shared.

    .venv/bin/python bench/fuzz.py [--runs N | --seconds S] [--harness NAME ...] [--artifact gains.json]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import sys
from pathlib import Path

from gainlink.firmware import fuzz
from gainlink.laws import design as design_spec
from gainlink.shipping import artifact as artifact_mod
from gainlink.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
TARGET_EXECUTIONS = 10_000_000


def load_artifact(path: str | None):
    if path:
        return artifact_mod.load(path)
    result = design_spec(load_spec(ROOT / "examples" / "pendulum.toml"))
    return artifact_mod.from_dict(result.artifact)


def run_one(name: str, exe: Path, artifact, out: Path, *, runs: int | None, seconds: float | None) -> dict:
    work = out / name
    shutil.rmtree(work, ignore_errors=True)
    corpus, crashes = work / "corpus", work / "crashes"
    seeds = fuzz.write_seeds(name, artifact, corpus)
    baseline = fuzz.run(name, exe, corpus, runs=0, artifacts=crashes)
    r = fuzz.run(name, exe, corpus, runs=runs, seconds=seconds, artifacts=crashes)
    return {
        "executions": r.executions,
        "seconds": round(r.seconds, 1),
        "exec_per_s": round(r.exec_per_s),
        "cov": r.cov,
        "ft": r.ft,
        "corpus": r.corpus,
        "seeds": seeds,
        "baseline_seed_cov": baseline.cov,
        "cov_vs_seeds": round(r.cov / baseline.cov, 3) if baseline.cov else None,
        "crashes": len(r.crashes),
        "crash_files": [str(Path(p).relative_to(ROOT)) for p in r.crashes],
        "libfuzzer_exit": r.exit_code,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=None, help=f"executions per harness (default {TARGET_EXECUTIONS})")
    ap.add_argument("--seconds", type=float, default=None, help="wall time per harness instead of --runs")
    ap.add_argument("--harness", action="append", choices=fuzz.HARNESSES, help="only these (repeatable)")
    ap.add_argument("--artifact", help="gains.json to build the harnesses for (default: the pendulum example)")
    args = ap.parse_args()
    runs = args.runs if args.runs is not None or args.seconds is not None else TARGET_EXECUTIONS
    logging.disable(logging.WARNING)
    os.nice(10)
    artifact = load_artifact(args.artifact)
    exes = fuzz.build_harnesses(artifact)
    out = ROOT / "out" / "fuzz"
    results = {
        name: run_one(name, exes[name], artifact, out, runs=runs, seconds=args.seconds)
        for name in (args.harness or fuzz.HARNESSES)
    }
    target = runs if runs is not None else TARGET_EXECUTIONS
    doc = {
        "benchmark": "fuzz",
        "engine": "libFuzzer (clang -fsanitize=fuzzer,address,undefined)",
        "artifact": artifact.name,
        "harnesses": results,
        "targets": {
            "executions_per_harness_min": TARGET_EXECUTIONS,
            "crashes_max": 0,
            "ok": all(r["executions"] >= TARGET_EXECUTIONS and r["crashes"] == 0 for r in results.values()),
            "requested_executions": target,
        },
    }
    json.dump(doc, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0 if all(r["crashes"] == 0 for r in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
