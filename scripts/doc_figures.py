"""Figures in the docs, from the benchmarks' JSON and from fresh builds: never typed in by hand.

The README and the pages under docs/ hold marked blocks, ``<!-- figures:NAME -->`` ... ``<!-- /figures:NAME -->``; this
script writes each block from the recorded results in ``bench/results/*.json`` (committed: the measurements the docs
show) and, for the figures a build measures cheaply (image sizes), from the firmware built now (cached builds).

    .venv/bin/python scripts/doc_figures.py                 rewrite the blocks
    .venv/bin/python scripts/doc_figures.py --record NAME   first copy out/bench/NAME.json (a fresh `make bench`)
                                                           into bench/results/ with when, where and at which commit
    .venv/bin/python scripts/doc_figures.py --check         exit 1 if a block differs from what it should say now

``scripts/bench.sh`` (``make bench``, ``make bench-fuzz``, ``make bench-soak``) records every benchmark that
succeeded; the test suite runs ``--check`` (tests/test_docs.py). A result whose ``recorded`` entry says ``from``
README was carried over from figures typed in before this script existed (its JSON was not kept); the block says so.

A figure older than the code it describes is flagged, in the docs themselves. :data:`SOURCES` names, per benchmark,
the files whose change can change its figures; a recording stores the sha256 of their content
(``recorded.sources_sha256``) and the commit it ran at. When their content now differs, the block says so (which
files changed since that commit, and the command that records it again), and ``--check`` fails until the block says
it: re-record the benchmark, or run this script to mark the figure as older than the code. Code the benchmark does
not measure can change freely: only these files count.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import hashlib
import json
import os
import re
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
OUT = ROOT / "out" / "bench"
BLOCK = re.compile(r"(<!-- figures:(?P<name>[a-z_]+) -->\n)(?P<body>.*?)(<!-- /figures:(?P=name) -->)", re.S)

Doc = dict[str, Any]

# The files each benchmark's figures depend on (folders are taken whole; __pycache__ aside).
_FIRMWARE_C = (
    "firmware/CMakeLists.txt",
    "firmware/cmake",
    "firmware/include",
    "firmware/src",
    "firmware/ports/cortex-m",
    "runtime/shipping/codegen.py",
    "runtime/laws/fixed/codegen.py",
    "runtime/laws/scheduled/codegen.py",
    "runtime/shipping/gains_layout.py",
    "runtime/shipping/export_c.py",
    "runtime/shipping/flags.py",
    "runtime/shipping/law_c.py",
    "runtime/shipping/params.py",
    "runtime/shipping/records.py",
)
_HOST_LINKS = ("hil/loop", "hil/links", "firmware/apps", "firmware/ports/host")
SOURCES: dict[str, tuple[str, ...]] = {
    "campaign": (
        "hil/campaign",
        "hil/loop/closed_loop.py",
        "hil/loop/endpoints.py",
        "hil/loop/block.py",
        "hil/plants/models.py",
        "hil/plants/linear.py",
        "runtime/laws/block.py",
        "runtime/proof/reference_step.py",
        "firmware/ports/host/gl_host.c",
        "bench/campaign.py",
    ),
    "cold_pages": ("hil/campaign", "hil/loop/block.py", "bench/campaign.py", "bench/cold_pages.py"),
    "firmware_cost": (*_FIRMWARE_C, "runtime/firmware/cost.py", "bench/firmware_cost.py"),
    "fixed_point_cost": (*_FIRMWARE_C, "runtime/laws/fixed/certificate.py", "bench/fixed_point_cost.py"),
    "fuzz": ("firmware/fuzz", "firmware/apps", "firmware/src", "bench/fuzz.py"),
    "hil_lockstep": (*_HOST_LINKS, "bench/hil_lockstep.py"),
    "hil_realtime": (*_HOST_LINKS, "bench/hil_realtime.py"),
    "mavlink_hil": (*_HOST_LINKS, "bench/mavlink_hil.py"),
    "mpc_cost": (
        *_FIRMWARE_C,
        "runtime/laws/mpc/codegen.py",
        "runtime/laws/mpc/block.py",
        "runtime/laws/mpc/design.py",
        "runtime/laws/mpc/cost.py",
        "runtime/firmware/cost.py",
        "runtime/firmware/branches.py",
        "runtime/firmware/paths.py",
        "examples/pendulum_mpc.toml",
        "examples/quadrotor_hover_mpc.toml",
        "bench/mpc_cost.py",
    ),
    "mpc_pays": (
        "hil/campaign",
        "hil/loop",
        "hil/plants",
        "runtime/laws/mpc",
        "runtime/laws/mpc/block.py",
        "runtime/synthesis",
        "firmware/src/gl_mpc.c",
        "examples/pendulum.toml",
        "examples/pendulum_mpc.toml",
        "examples/campaigns/pendulum_mpc_mass_uncertainty.toml",
        "bench/mpc_pays.py",
    ),
    "sched_cost": (*_FIRMWARE_C, "firmware/ports/host", "bench/sched_cost.py"),
    "sched_showcase": (
        "runtime/synthesis",
        "hil/loop",
        "hil/fmus/tank",
        "examples/tank_showcase.toml",
        "hil/scenarios/tank_showcase.toml",
        "bench/sched_showcase.py",
    ),
    "soak": (*_HOST_LINKS, "bench/soak.py"),
    "target_uart": ("firmware/apps", "firmware/ports/cortex-m", "hil/links", "bench/target_uart.py"),
}


def pages() -> list[Path]:
    """The pages that may hold figures: README.md and every Markdown page of docs/ (not its build)."""
    docs = sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.relative_to(ROOT / "docs").parts)
    return [ROOT / "README.md", *docs]


# --- how old a figure is ----------------------------------------------------------------------------------------


def _source_files(paths: Iterable[str]) -> list[Path]:
    """The files under ``paths`` that git tracks (what a build or a test run writes there is not code), or, outside a
    git checkout, every file under them but bytecode."""
    paths = list(paths)
    tracked = _git("ls-files", "-z", "--", *paths)
    if tracked is not None:
        names = sorted({name for name in tracked.split("\0") if name})
        return [ROOT / name for name in names if (ROOT / name).is_file()]
    files: set[Path] = set()
    for rel in paths:
        path = ROOT / rel
        found = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
        files |= {p for p in found if "__pycache__" not in p.parts and p.suffix != ".pyc"}
    return sorted(files, key=lambda p: p.relative_to(ROOT).as_posix())


def sources_digest(name: str) -> str:
    """sha256 over the paths and contents of the files :data:`SOURCES` names for benchmark ``name``."""
    digest = hashlib.sha256()
    for path in _source_files(SOURCES.get(name, ())):
        digest.update(f"{path.relative_to(ROOT).as_posix()}\0".encode())
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


def _git(*argv: str) -> str | None:
    try:
        proc = subprocess.run(["git", *argv], cwd=ROOT, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    except OSError:
        return None
    return proc.stdout.strip() if proc.returncode == 0 else None


def staleness(name: str, doc: Doc) -> str | None:
    """None when the files benchmark ``name`` measures are as they were when it was recorded (or the recording
    does not say: see :func:`provenance`); else which of them changed (for messages: the docs say it in words that
    do not change with every later change, so that a figure flagged once stays flagged without another edit)."""
    rec = doc.get("recorded", {})
    recorded = rec.get("sources_sha256")
    if recorded is None or recorded == sources_digest(name):
        return None
    commit = rec.get("commit")
    changed = _git("diff", "--name-only", commit, "--", *SOURCES[name]) if commit else None
    files = changed.splitlines() if changed else []
    listed = ", ".join(files[:6]) + (f" and {len(files) - 6} more" if len(files) > 6 else "")
    return f"{listed or 'the files it measures'} changed since it was recorded"


# --- reading and recording --------------------------------------------------------------------------------------


def result(name: str) -> Doc | None:
    """bench/results/NAME.json, or None when that benchmark was never recorded."""
    path = RESULTS / f"{name}.json"
    return json.loads(path.read_text("utf-8")) if path.is_file() else None


def record(name: str) -> Path:
    """Copy out/bench/NAME.json to bench/results/NAME.json, stamped with the date, the machine's load, the commit
    and the state of the files it measures."""
    src = OUT / f"{name}.json"
    doc = json.loads(src.read_text("utf-8"))
    stamp = {
        "from": f"bench/{name}.py",
        "date": datetime.date.today().isoformat(),
        "cpus": os.cpu_count(),
        "load_average_at_record": round(os.getloadavg()[0], 2),
        "commit": _git("rev-parse", "HEAD"),
        "sources_sha256": sources_digest(name),
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    dst = RESULTS / f"{name}.json"
    tmp = dst.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"recorded": stamp, **doc}, indent=2) + "\n", "utf-8")
    os.replace(tmp, dst)
    return dst


def prose(text: str, indent: str = "") -> str:
    """``text`` wrapped at the docs' 120 columns (continuation lines indented by ``indent``)."""
    return "\n".join(textwrap.wrap(text, 120, subsequent_indent=indent, break_on_hyphens=False))


def provenance(doc: Doc) -> str:
    """Sentences saying where a result comes from, and whether it is older than the code it describes."""
    rec = doc.get("recorded", {})
    name = rec.get("from", "").removeprefix("bench/").removesuffix(".py")
    if "README" in rec.get("from", ""):
        return prose(
            f"Recorded result carried over from the README (its JSON was not kept): {rec.get('conditions', '')}."
        )
    load = run_load(doc)
    if load is not None:
        where = f"{rec.get('cpus', '?')} CPUs; the benchmark saw a load average of {load:.1f}"
    else:
        where = f"{rec.get('cpus', '?')} CPUs, load average {rec.get('load_average_at_record', 0):g} when recorded"
    at = f" at commit {rec['commit'][:10]}" if rec.get("commit") else ""
    text = f"`{rec.get('from', '?')}`, recorded {rec.get('date', '?')}{at} ({where})."
    stale = staleness(name, doc)
    if rec.get("sources_sha256") is None:
        text += " Not dated against the code it measures (recorded before recordings said which)."
    elif stale is not None:
        text += (
            " **Older than the code it describes**: files it measures (`SOURCES` in `scripts/doc_figures.py`) changed"
            f" since it was recorded; `scripts/bench.sh {name}` records it again."
        )
    return prose(text)


def run_load(doc: Doc) -> float | None:
    """The 1-minute load average a benchmark wrote into its own JSON (each names it its own way), if any."""
    for key in ("load_average_1min", "load_avg_1min", "load_average_before"):
        value = doc.get(key)
        if value is not None:
            return float(value[0] if isinstance(value, list) else value)
    return None


def missing(what: str, target: str) -> str:
    return f"No {what} recorded yet: `{target}` measures it.\n"


# --- image sizes, measured now ----------------------------------------------------------------------------------


@functools.cache
def image_sizes() -> dict[tuple[str, str], Doc]:
    """Flash and RAM of the pendulum's images, built now (cached builds, as the test suite's): the float32 image on
    every core (``("float32", target)``) and, for the cores of ``bench/fixed_point_cost.py``, the two images it counts
    of its q31 design (``("q31", target)``: the integer law's replay image; ``("q31-float32", target)``: the float32
    baseline of the same export, ``GL_LAW=lq_float32``)."""
    import logging

    from gainlink.firmware.build import build
    from gainlink.firmware.size import size_report
    from gainlink.firmware.targets import CORTEX_M_TARGETS, TARGETS
    from gainlink.laws import design as design_spec
    from gainlink.laws.fixed import firmware as fixed
    from gainlink.shipping.artifact import from_dict
    from gainlink.spec import load_spec

    sys.path.insert(0, str(ROOT / "bench"))
    from fixed_point_cost import BASELINE, CORES, pendulum_q31

    logging.disable(logging.WARNING)
    pendulum = from_dict(design_spec(load_spec(ROOT / "examples" / "pendulum.toml")).artifact)
    sizes: dict[tuple[str, str], Doc] = {}
    for target in CORTEX_M_TARGETS:
        board = TARGETS[target].default_board
        sizes["float32", target] = size_report(build(pendulum, target=target).files["elf"], board=board)
    q31 = pendulum_q31()
    for target in CORES:
        board = TARGETS[target].default_board
        elf_q, _ = fixed.image(q31, target=target, options=fixed.REPLAY_OPTIONS)
        sizes["q31", target] = size_report(elf_q, board=board)
        sizes["q31-float32", target] = size_report(
            build(q31, target=target, options=BASELINE).files["elf"], board=board
        )
    return sizes


# --- formatting helpers -----------------------------------------------------------------------------------------


def num(v: float | None, digits: int = 0) -> str:
    """A figure with thousands separators (``—`` when absent)."""
    return "—" if v is None else f"{v:,.{digits}f}"


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


# --- the blocks -------------------------------------------------------------------------------------------------

HARNESSES = ("can_udp", "can_layout", "slcan", "mavlink_node", "gains_stage")


def fuzz_block() -> str:
    doc = result("fuzz")
    if doc is None:
        return missing("fuzzing run", "make bench-fuzz")
    runs = doc.get("harnesses", {})
    rows = []
    for name in HARNESSES:
        r = runs.get(name)
        if r is None:
            rows.append([f"`{name}`", "not recorded", "", "", "", ""])
            continue
        rows.append(
            [
                f"`{name}`",
                num(r["executions"]),
                f"{num(r['seconds'])} s ({num(r['exec_per_s'])}/s)",
                f"{r['cov']} vs {r['baseline_seed_cov']} ({num(r.get('cov_vs_seeds'), 2)}x)",
                f"{r.get('ft', '—')} / {r.get('corpus', '—')}",
                str(r["crashes"]),
            ]
        )
    head = ["harness", "executions", "time", "cov vs the seeds'", "ft / corpus", "crashes"]
    return table(head, rows) + "\n" + provenance(doc) + "\n"


def soak_block() -> str:
    doc = result("soak")
    if doc is None:
        return missing("soak run", "make bench-soak")
    rows = []
    for phase in ("lockstep", "realtime"):
        p = doc.get(phase)
        if p is None:
            continue
        misses = p.get("misses", {}).get("missed") if phase == "realtime" else None
        rows.append(
            [
                phase,
                f"{num(p['wall_s'] / 60, 1)} min",
                num(p["steps"]),
                num(p["steps_per_s"]),
                num(p.get("bridge_rss_slope_minus_trace"), 1),
                num(p.get("firmware_rss_slope_kib_per_min"), 1),
                str(p["books"].get("unaccounted_bridge", "—")),
                "—" if misses is None else num(misses),
            ]
        )
    head = ["phase", "length", "steps", "steps/s", "bridge RSS KiB/min (less its trace)", "firmware RSS KiB/min"]
    head += ["unaccounted samples", "deadline misses"]
    return table(head, rows) + "\n" + provenance(doc) + "\n"


def campaign_block() -> str:
    doc = result("campaign")
    if doc is None:
        return missing("campaign benchmark", "make bench")
    sil, hil, ovh, mem = doc["sil"], doc["hil"], doc["overhead"], doc["memory"]
    plain = sil.get("plain_processes", {}).get("speedup_2_vs_1")
    lines = [
        f"- speed-up of {sil['runs']} SIL runs, 2 workers over 1: **{sil['speedup_2_vs_1']:.2f}x** of wall time "
        f"(target {sil['target_speedup']}); per second of the runs' own CPU {sil['speedup_2_vs_1_per_run_cpu']:.2f}x; "
        f"the same runs in 2 plain processes without Dask: {num(plain, 2)}x",
        f"- {hil['runs']} HIL runs, 2 workers over 1: {hil['speedup_2_vs_1']:.2f}x",
        f"- machinery CPU per run: **{ovh['overhead_ratio']:+.1%}** of the runs' own (target "
        f"{ovh['target_overhead_ratio']:.0%}; {ovh['overhead_ratio_without_report']:+.1%} without the report, "
        f"{ovh['report_cpu_s']:.2f} s per campaign); against the plain loop {ovh['overhead_ratio_vs_plain_loop']:+.1%}",
        f"- worker memory {mem['worker_rss_after_40_runs_mb']:.1f} MB after 40 runs, "
        f"{mem['worker_rss_after_440_runs_mb']:.1f} MB after 440 ({'flat' if mem['flat'] else 'growing'})",
        f"- load average (1, 5, 15 min) before {', '.join(map(str, doc['load_average_before']))}, after "
        f"{', '.join(map(str, doc['load_average_after']))}, on {doc['machine_cpus']} CPUs: other work on the machine "
        "takes from the 2-worker side first",
    ]
    lines += _block_lines(doc.get("blocks"))
    return "\n".join(prose(line, "  ") for line in lines) + "\n\n" + provenance(doc) + "\n"


def _block_lines(blocks: dict | None) -> list[str]:
    """The block benchmark's lines (campaign blocks), when the recording has them."""
    if not blocks:
        return ["- campaign blocks: not in this recording (`scripts/bench.sh campaign` records them)"]
    ten, per_run = blocks["ten_thousand"], blocks["per_run_path"]
    lines = [
        f"- blocks, the shipped pendulum campaign at {ten['runs']} runs of {ten['steps_per_run']} steps on 2 workers: "
        f"**{ten['wall_s']:.1f} s** wall, report included (target {blocks['target_ten_thousand_wall_s']} s; cluster "
        f"start {ten['cluster_start_s']:.1f} s apart); the runs' own CPU "
        f"**{ten['runs_own_cpu_per_run_step_us']:.2f} us** per run-step (target "
        f"{blocks['target_cpu_per_run_step_us']}), {blocks['block_vs_per_run_path']:.0f}x less than the per-run path "
        f"in the same run ({per_run['cpu_per_run_step_us']:.0f} us; target "
        f"{blocks['target_block_vs_per_run_path']}x); machinery {_machinery(blocks, ten)}; client peak RSS "
        f"+{ten['client_peak_rss_growth_mb']:.0f} MB, "
        f"worker {ten['worker_rss_mb']:.0f} MB, {ten['result_files']} result files",
        f"- blocks, 2 workers over 1 ({'-'.join(map(str, blocks.get('order', (1, 2, 2, 1))))}, "
        f"{blocks['speedup_runs'][0]['runs']} runs each): "
        f"**{blocks['speedup_2_vs_1']:.2f}x** (target {blocks['target_speedup']}){_ceiling(blocks)}{_small(blocks)}",
    ]
    large = blocks.get("hundred_thousand")
    if large:
        lines.append(
            f"- blocks at {large['runs']} runs: {large['wall_s']:.0f} s wall ({large['runs_wall_s']:.0f} s until the "
            f"last run is stored, the report {large['report_cpu_s']:.0f} s of CPU), client peak RSS "
            f"+{large['client_peak_rss_growth_mb']:.0f} MB over its {large['client_rss_start_mb']:.0f} MB at the start "
            f"(the bench's client, grown by the campaigns before), {large['result_files']} result files{_large(blocks)}"
        )
    return lines


def _ceiling(blocks: dict) -> str:
    """What 2 plain processes give the same block work here (no Dask, client or report), when recorded."""
    plain = blocks.get("plain_processes")
    if not plain:
        return ""
    return (
        f"; {blocks['speedup_2_vs_1_runs']:.2f}x until the last run is stored, {_per_run_cpu(blocks):.2f}x per second "
        f"of the runs' own CPU (the host's slower CPUs on one side taken out); the same block work in 2 plain "
        f"processes without Dask: {plain['speedup_2_vs_1']:.2f}x, the machine's ceiling{_by_pair(blocks)}"
    )


def _by_pair(blocks: dict) -> str:
    """The ceiling and the campaigns' 2-over-1 pair of clusters by pair, when the ceiling was measured beside each."""
    ceilings, speeds = blocks["plain_processes"].get("speedup_2_vs_1_by_pair"), blocks.get("speedup_2_vs_1_by_pair")
    if not ceilings or not speeds:
        return ""
    pairs = ", ".join(f"{campaign:.2f}x/{ceiling:.2f}x" for campaign, ceiling in zip(speeds, ceilings))
    return f" at the same moments (measured before each cluster's campaign; pair by pair, campaign/ceiling: {pairs})"


def _per_run_cpu(blocks: dict) -> float:
    """2 workers over 1 at the block benchmark's campaigns, each side's wall per second of its runs' own CPU (what the
    SIL line says "per second of the runs' own CPU"): the same runs cost one side more CPU when the host's CPUs gave
    less while it ran."""
    side = {n: [c for c in blocks["speedup_runs"] if c["workers"] == n] for n in (1, 2)}
    per_cpu = {n: sum(c["wall_s"] for c in cs) / sum(c["runs_own_cpu_s"] for c in cs) for n, cs in side.items()}
    return per_cpu[1] / per_cpu[2]


def _small(blocks: dict) -> str:
    """The 2-workers-over-1 of the smaller campaign, when recorded (its report a larger share of its wall)."""
    small = blocks.get("small_campaigns")
    if not small:
        return ""
    return (
        f"; at {small[0]['runs']} runs {blocks['speedup_2_vs_1_small']:.2f}x "
        f"({blocks['speedup_2_vs_1_small_runs']:.2f}x until the last run is stored: the report's ~"
        f"{_mean_of(small, 'report_cpu_s'):.1f} s of CPU is a larger share of a smaller campaign)"
    )


def _large(blocks: dict) -> str:
    """The 2-workers-over-1 at the larger campaign (1-2-2-1 at 100,000 draws), when recorded."""
    if "speedup_2_vs_1_large" not in blocks:
        return ""
    return (
        f"; 2 workers over 1 at this size (1-2-2-1): **{blocks['speedup_2_vs_1_large']:.2f}x** (target "
        f"{blocks['target_speedup']}; {blocks['speedup_2_vs_1_large_runs']:.2f}x until the last run is stored)"
    )


def _mean_of(rows: list[dict], key: str) -> float:
    return sum(r[key] for r in rows) / len(rows)


def _machinery(blocks: dict, ten: dict) -> str:
    """The machinery's share: the part a run adds (the target's figure) and the fixed part, when recorded apart."""
    whole = f"{ten['machinery_ratio']:+.0%} of the runs' own CPU over the whole campaign"
    split = blocks.get("machinery")
    if not split:
        return f"**{whole}** (target {blocks['target_machinery_ratio']:.0%})"
    parts = split.get("per_run_ms_by_part")
    where = (
        ""
        if not parts
        else f": {parts['workers_outside_runs']:.2f} ms in the workers outside the runs, "
        f"{parts['client_until_stored']:.2f} in the client until the last run is stored, {parts['report']:.2f} in the "
        "report"
    )
    slope = f"the slope over {split['from_runs'][0]} and {split['from_runs'][1]} runs{where}"
    if blocks.get("machinery_fit"):
        head = f"{_fit(blocks)}; between the means of two sizes alone {split['per_run_ratio']:+.0%} ({slope})"
    else:
        head = (
            f"a run adds **{split['per_run_ratio']:+.0%}** of its own CPU (target "
            f"{blocks['target_machinery_ratio']:.0%}; {slope})"
        )
    fixed = f" and a campaign {split['fixed_s']:.1f} s whatever its size ({whole})"
    return f"{head}{fixed}{_slope_large(blocks)}{_kernel(blocks)}"


def _fit(blocks: dict) -> str:
    """The machinery a run adds by the line through every 2-worker campaign (the target's figure), when recorded."""
    fit = blocks["machinery_fit"]
    return (
        f"a run adds **{fit['per_run_ratio']:+.1%}** of its own CPU, +/- {fit['per_run_ratio_stderr']:.1%} (target "
        f"{blocks['target_machinery_ratio']:.0%}; the line through the {fit['campaigns']} campaigns of "
        f"{', '.join(map(str, fit['from_runs']))} runs on 2 workers)"
    )


def _kernel(blocks: dict) -> str:
    """The workers' kernel CPU a run adds and this machine's cost of new pages, when recorded."""
    split, pages = blocks.get("machinery_large") or blocks.get("machinery"), blocks.get("page_costs_before")
    if not pages or not split or "workers_kernel_per_run_ms" not in split:
        return ""
    return (
        f"; the workers' kernel CPU a run adds (system time, the runs' and the rest's) "
        f"{split['workers_kernel_per_run_ms']:.3f} ms; a new page-cache page costs this machine "
        f"{pages['new_file_write_ms_per_mb']:.2f} ms a MB written (the same bytes written over them again "
        f"{pages['file_rewrite_ms_per_mb']:.2f}; new memory {pages['new_memory_ms_per_mb']:.2f}), measured before the "
        "benchmark"
    )


def _slope_large(blocks: dict) -> str:
    """The machinery a run adds from the 10,000- to the 100,000-run campaigns, when recorded."""
    large = blocks.get("machinery_large")
    if not large:
        return ""
    return f"; over {large['from_runs'][0]} and {large['from_runs'][1]} runs a run adds {large['per_run_ratio']:+.0%}"


def loop_rates_block() -> str:
    rows = []
    lock = result("hil_lockstep")
    if lock is not None:
        base = lock["baseline"]["steps_per_s"]
        for key, label in (
            ("can_fd", "CAN FD, commands on a reply_port, bridge and firmware sharing a CPU (the default placement)"),
            ("can_fd_one_port", "CAN FD, both directions on one port"),
            ("can_fd_unpinned", "CAN FD, placement left to the kernel"),
            ("classic_can", "classic CAN (3 + 1 frames a step)"),
            ("can_fd_busy_poll", "CAN FD, busy polling"),
            ("link_floor", "the link alone (CAN FD sample out, command back; no plant, no loop)"),
        ):
            if key not in lock:  # a recording from before the run existed
                continue
            rate = lock[key]["steps_per_s"]
            rows.append([f"lockstep, udp_multicast: {label}", num(rate), f"{rate / base:.2f} of in-process"])
    mav = result("mavlink_hil")
    if mav is not None:
        for key, label in (("default", "default"), ("busy_poll", "busy polling")):
            r = mav[key]
            rows.append(
                [
                    f"lockstep, MAVLink over UDP: {label}",
                    num(r["steps_per_s"]),
                    f"{r['ratio_vs_in_process']:.2f} of in-process",
                ]
            )
    rt = result("hil_realtime")
    if rt is not None:
        j = rt["period_jitter_us"]
        floor = rt.get("machine_floor", {}).get("p99")
        rows.append(
            [
                f"realtime 1 kHz, {rt['seconds']:g} s, CAN FD",
                f"jitter p99 {num(j['p99'])} us, max {num(j['max'])} us",
                f"{rt['deadline_misses']} deadline misses in {num(rt['steps'])}"
                + (f"; cyclictest p99 {num(floor)} us" if floor is not None else ""),
            ]
        )
    if not rows:
        return missing("loop rate", "make bench")
    sources = [d for d in (lock, mav, rt) if d is not None]
    cpu = "" if lock is None else lockstep_cpu_line(lock)
    return (
        table(["loop", "steps/s", "against the baseline"], rows)
        + "\n"
        + cpu
        + "\n".join(map(provenance, sources))
        + "\n"
    )


def lockstep_cpu_line(lock: dict) -> str:
    """The CAN runs' CPU time per step (what a loaded machine's wall-clock rates hide), when recorded."""
    parts = [
        f"{label} {runs[key]['cpu_us_per_step'][a]:.1f} + {runs[key]['cpu_us_per_step'][b]:.1f} us"
        for key, label, a, b, runs in (
            ("can_fd", "CAN FD with a reply port", "loop", "firmware", lock),
            ("can_fd_one_port", "on one port", "loop", "firmware", lock),
            ("link_floor", "the link alone", "bridge", "firmware", lock),
        )
        if key in runs and isinstance(runs[key].get("cpu_us_per_step"), dict)
    ]
    if not parts:
        return ""
    base = lock["baseline"].get("cpu_us_per_step")
    tail = f"; the in-process baseline {base:.1f} us" if base is not None else ""
    return prose(f"CPU time a step, the bridge's loop + the firmware: {', '.join(parts)}{tail}.", "") + "\n"


def target_uart_block() -> str:
    doc = result("target_uart")
    if doc is None:
        return missing("UART benchmark", "make bench")
    rows = []
    for name, r in doc["round_trips"].items():
        best = doc.get("realtime", {}).get(name, {}).get("highest_rate_hz_without_miss")
        rows.append(
            [
                name.replace("_", " "),
                num(r.get("round_trips_per_s")),
                f"{r['latency_us_p50'] / 1000:.2f} / {r['latency_us_p99'] / 1000:.2f} ms",
                "" if best is None else f"{best:g} Hz",
            ]
        )
    head = ["link (pendulum, one sample in flight)", "round trips/s", "latency p50 / p99"]
    head += [f"highest {doc['realtime_seconds_each']:g} s realtime rate without a miss"]
    return table(head, rows) + "\n" + provenance(doc) + "\n"


def _flash_ram(kind: str, target: str) -> tuple[str, str]:
    size = image_sizes()[kind, target]
    return num(size["flash_bytes"]), num(size["ram_bytes_without_stack"])


def fixed_point_cost_block() -> str:
    doc = result("fixed_point_cost")
    if doc is None:
        return missing("fixed-point cost", "python bench/fixed_point_cost.py")
    rows = []
    for r in doc["per_target"]:
        plain = r.get("float32_plain_fma_instructions_per_step")
        ratio = f"{r['ratio_float32_to_q31']:g}x"
        if plain is not None:
            ratio += f" / {r['ratio_float32_plain_to_q31']:g}x"
        (q_flash, q_ram), (f_flash, f_ram) = _flash_ram("q31", r["target"]), _flash_ram("q31-float32", r["target"])
        rows.append(
            [
                f"{r['target']} ({r['board']})",
                num(r["q31_instructions_per_step"]),
                num(r["float32_instructions_per_step"]),
                "—" if plain is None else num(plain),
                ratio,
                f"{q_flash} / {f_flash} B",
                f"{q_ram} / {f_ram} B",
            ]
        )
    head = ["core (board)", "q31", "float32 as built", "float32 plain multiply-add", "float32 / q31"]
    head += ["flash q31 / float32 image", "RAM (no stack) q31 / float32 image"]
    sizes = "Flash and RAM: the images built now (the docs' test builds them and compares)."
    return table(head, rows) + "\n" + provenance(doc) + "\n" + sizes + "\n"


FPU = {"cortex-m0": "none", "cortex-m3": "none", "cortex-m4": "FPv4-SP", "cortex-m7": "FPv5-DP"}
FPU |= {"cortex-m33": "FPv5-SP", "cortex-m55": "FPv5-DP + Helium"}


def cortex_m_targets_block() -> str:
    """The pendulum's float32 step on every core: instructions (bench/firmware_cost.py's per_target) and the sizes
    of the images built now."""
    doc = result("firmware_cost")
    if doc is None or "per_target" not in doc:
        return missing("per-core cost", "python bench/firmware_cost.py")
    rows = []
    for r in doc["per_target"]:
        size = image_sizes()["float32", r["target"]]
        stack = size["ram_bytes"] - size["ram_bytes_without_stack"]
        rows.append(
            [
                r["target"],
                r["board"],
                FPU.get(r["target"], "?"),
                f"{r['instructions_per_step']:g} ({r['dearest_step_instructions']})",
                f"{r['own_instructions_per_step']:g}",
                f"{num(size['flash_bytes'])} B",
                f"{num(size['ram_bytes_without_stack'])} + {num(stack)} B",
            ]
        )
    head = ["target", "board", "FPU", "instructions per step (dearest)", "inside `gl_loop_step`", "flash"]
    head += ["RAM + stack"]
    soft = {r["target"]: r for r in doc["per_target"] if "gl_fmaf_instructions_per_call" in r}
    words = []
    for target, r in soft.items():
        words.append(
            f"on the {target.removeprefix('cortex-').upper()} `gl_fmaf` costs {r['gl_fmaf_instructions_per_call']:g} "
            f"instructions per call ({r['gl_fmaf_calls_per_step']:g} calls per step), the same step with newlib's "
            f"`fmaf` {num(r['baseline_newlib_fma_instructions_per_step'])} instructions (not bit for bit) and with a "
            f"plain multiply then add {num(r['baseline_plain_fma_instructions_per_step'])}"
        )
    fmaf = prose("Soft-float cores: " + "; ".join(words) + ".") + "\n" if words else ""
    sizes = "Flash and RAM: the images built now (the docs' test builds them and compares)."
    return table(head, rows) + "\n" + fmaf + "\n" + provenance(doc) + "\n" + sizes + "\n"


def _step(row: Doc, name: str) -> str:
    st = row[f"step_{name}"]
    if st["settling_time_s"] is None:  # a result recorded since the showcase stopped giving a run's end as a time
        return f"{st['overshoot_pct']:.1f} % / not settled (a limit cycle)"
    tail = "" if st["settled"] else ", not settled (a limit cycle)"
    return f"{st['overshoot_pct']:.1f} % / {st['settling_time_s']:.2f} s{tail}"


def sched_showcase_block() -> str:
    doc = result("sched_showcase")
    if doc is None:
        return missing("scheduled showcase", "python bench/sched_showcase.py")
    rows = []
    for name, label in (("single", f"single point ({doc['single_point']:g} m)"), ("scheduled", "scheduled")):
        r = doc["designs"][name]
        rows.append(
            [
                label,
                f"{r['sweep_iae']:.3f}",
                f"{r['sweep_max_abs_e']:.3f} m",
                f"{r['sweep_hold_max_abs_e']:.2g} m",
                *(_step(r, step) for step in doc["steps"]),
                f"{r['model_twin_worst']:.4f}" + (" (warns)" if r["model_twin_warning"] else ""),
                f"{r['twin_worst_du_rel']:.1e}",
            ]
        )
    head = ["design", "sweep IAE", "sweep max abs e", "held at the low end, max abs e"]
    head += [f"step {s['from']:g} → {s['to']:g} m: overshoot / settling" for s in doc["steps"].values()]
    head += ["model twin mismatch", "C vs float64 twin (du)"]
    return table(head, rows) + "\n" + provenance(doc) + "\n"


def sched_cost_block() -> str:
    doc = result("sched_cost")
    if doc is None:
        return missing("scheduled step cost", "python bench/sched_cost.py")
    m4, host = doc["cortex_m4"], doc["host"]
    rows = [
        [
            "Cortex-M4F (instructions per step)",
            num(m4["unscheduled_instructions_per_step"]),
            f"{num(m4['scheduled_sigma_moving_instructions_per_step'])} ({m4['ratio_sigma_moving']:.2f}x)",
            f"{num(m4['scheduled_sigma_standing_instructions_per_step'])} ({m4['ratio_sigma_standing']:.2f}x)",
        ],
        [
            "host (ns per step)",
            f"{host['unscheduled_ns_per_step']:g}",
            f"{host['scheduled_sigma_moving_ns_per_step']:g} ({host['ratio_sigma_moving']:.2f}x)",
            f"{host['scheduled_sigma_standing_ns_per_step']:g} ({host['ratio_sigma_standing']:.2f}x)",
        ],
    ]
    head = ["tank, 5 points", "unscheduled", "scheduled, sigma moving", "scheduled, sigma standing"]
    target = f"Target: at most {doc['targets']['ratio_max']:g}x the unscheduled step (DESIGN.md).\n\n"
    return target + table(head, rows) + "\n" + provenance(doc) + "\n"


def bound_words(proved: bool, proof: dict) -> str:
    """The words beside an MPC bound: proved (on a soft-float core, how loose: bound over the measured worst), or
    measured."""
    if not proved:
        return "measured, not proved"
    if "bound_over_measured_worst" in proof:
        return f"proved, soft float: {proof['bound_over_measured_worst']:g}x the measured worst"
    return "proved"


def mpc_cost_block() -> str:
    """The MPC law's step on the M0, M3, M4F, M7, M33 and M55 (bench/mpc_cost.py): instructions per step, mean and
    worst, per iteration, the bound at the cap (proved or measured, and what it covers), the attempt to break it,
    sizes; against the issue's targets and the LQ law of the same weights."""
    doc = result("mpc_cost")
    if doc is None:
        return missing("MPC step cost", "scripts/bench.sh mpc_cost")
    rows = [_mpc_cost_row(d, r) for d in doc["designs"] for r in d["targets"]]
    notes = [_mpc_cost_note(d) for d in doc["designs"]]
    head = ["design", "core", "iterations mean / worst", "instructions per step mean / worst", "per iteration"]
    head += ["bound at the cap", "worst found trying to break it", "tables (one bank)", "state + workspace"]
    head += ["both banks + state"]
    return (
        table(head, rows)
        + "\n"
        + "\n".join(prose(n) for n in notes)
        + "\n\n"
        + _mpc_cost_caveat()
        + "\n\n"
        + provenance(doc)
        + "\n"
    )


def _mpc_cost_row(d: Doc, r: Doc) -> list[str]:
    """One core's row of a design's MPC step cost: iterations, instructions, the bound and the attempt to break it,
    the sizes; or why it was not built."""
    core = r["target"].removeprefix("cortex-").upper() + ("F" if r["target"] == "cortex-m4" else "")
    if not r.get("built", True):
        return [d["design"], core, "not built: the law's replay image does not fit the board's RAM"] + ["—"] * 7
    proof = r.get("proof", {})
    proved = r.get("bound_proved", False)
    tried = f"{num(proof['adversarial_worst'])} over {proof['adversarial_steps']} steps" if proved else "—"
    return [
        d["design"], core,
        f"{r['iterations_mean']:g} / {r['iterations_max']} ({r['capped_steps']}/{r['steps']} capped)",
        f"{num(r['instructions_per_step_mean'])} / {num(r['instructions_per_step_worst'])}",
        num(proof["per_iteration"]) if proved else num(r["instructions_per_iteration_worst"]),
        f"{num(r['bound_per_step_at_cap'])} ({bound_words(proved, proof)})",
        tried,
        f"{num(r['tables_bytes'])} B",
        f"{num(r['law_state_and_workspace_bytes'])} B",
        f"{num(r['law_ram_with_both_banks_bytes'])} B",
    ]  # fmt: skip


def _mpc_cost_note(d: Doc) -> str:
    """A design's sentence under the table: its M4F worst and proved bound against the target, the LQ law of the
    same weights, and its RAM against 16 KiB."""
    m4 = next(r for r in d["targets"] if r["target"] == "cortex-m4")
    target = d.get("target_m4f_instructions_per_step_worst")
    words = (f"{d['design']} (N = {d['horizon']}, cap {d['cap']}, {d['macs_per_iteration']:,} multiply-adds per "
             f"iteration): M4F worst {num(m4['instructions_per_step_worst'])} instructions per step, proved bound "
             f"{num(m4['bound_per_step_at_cap'])}")  # fmt: skip
    if target:
        verdict = "within" if d.get("m4f_bound_within_target") else "OVER"
        words += f", {verdict} the target of {num(target)}"
    base = d["baseline_m4f"]
    words += (f"; the LQ law of the same weights takes {num(base['instructions_per_step_worst'])} "
              f"({d['ratio_to_baseline_worst']:g}x)")  # fmt: skip
    if "m4f_law_ram_with_both_banks_within_16KiB" in d:
        ok = "within" if d["m4f_law_ram_with_both_banks_within_16KiB"] else "OVER"
        words += f"; state, workspace and both banks {num(m4['law_ram_with_both_banks_bytes'])} B, {ok} 16 KiB"
    return words + "."


def _mpc_cost_caveat() -> str:
    """What an MPC step's instruction count and its bound cover, and on what premises."""
    return prose(
        "Instructions, not cycles: a `vfma.f32` takes 3 cycles on the M4F and flash wait states add more, so no time "
        "is given. A bound marked proved holds for every input (any samples, references, warm start and numbers in "
        "tables of these dimensions) on the image measured: that core, the compiler flags the bench prints, the "
        "design's horizon, states, inputs and box rows. It rests on the disassembly of that image (the law's numbers "
        "decide only the non-finite tests and the solver's stopping test; the box projections are IT-block selects) "
        "and on a run that fits fixed part + iterations x one iteration exactly; premises: a word an integer register "
        "loads and only moves, offsets and compares is an address, and an index added to a stack frame's address is "
        "not negative (the analysis tracks the stack slots a function spills to and reloads from). On the M0 and the "
        "M3 (soft float: the paths of `gl_fmaf` and the float routines depend on their operands) the bound is proved "
        "another way: every float routine the step calls is charged at its longest path on the disassembly, "
        "loop-free but for libgcc's normalisation of a subnormal operand in the M3's `__aeabi_fmul` (premise: at "
        "most 22 times back, its mantissa nonzero), the compare-decided clamps are detours charged at their longest "
        "path, and a refused step is bounded by the heaviest path to `refuse`; a further premise there is that the "
        "step's branches before `solve` are its non-finite tests. It is loose, because every routine is charged at "
        "its dearest path. The quadrotor's M3 bound is measured, not proved: its non-finite tests are a loop on the "
        "way to `refuse`, which the refused step's path search does not bound."
    )


def _pays_cell(s: Doc) -> list[str]:
    settle = "—" if s["settling_s_median"] is None else f"{s['settling_s_median']:.2f} s ({s['settled_runs']} settle)"
    iae = "—" if s["iae_median_of_runs_up"] is None else f"{s['iae_median_of_runs_up']:.2f}"
    return [f"{100 * s['stays_up']:.0f} % of {s['runs']}", settle, iae]


def mpc_pays_block() -> str:
    """MPC against LQI + back-calculation on the same drawn pendulums (and the MPC with a soft box on the angle), and
    the MPC over rho x cap (bench/mpc_pays.py)."""
    doc = result("mpc_pays")
    if doc is None:
        return missing("MPC campaign comparison", "scripts/bench.sh mpc_pays")
    laws = (("mpc", "MPC (N = 20, cap 10)"), ("mpc_theta_box", "MPC, soft box abs(theta) <= 0.4 rad"),
            ("lqi_backcalc", "LQI + back-calculation"))  # fmt: skip
    rows = []
    for entry in doc["compare"].values():
        for law, label in laws:
            s = entry[law]
            it = "—"
            if "iterations_mean" in s:
                it = (f"{s['iterations_mean']:.1f} / {s['iterations_worst']}, "
                      f"{100 * s['capped_fraction_of_steps']:.0f} % of steps capped")  # fmt: skip
            fell = ", ".join(f"{k} {v}" for k, v in sorted(s.get("failed_criteria", {}).items())) or "—"
            rows.append([f"±{entry['box_N']:g} N", label, *_pays_cell(s), fell, it])
    head = ["box", "law", "stays up", "settling median (runs up)", "IAE median (runs up)"]
    head += ["runs failing each criterion", "iterations mean / worst"]
    pairs = "; ".join(
        f"at ±{e['box_N']:g} N the MPC keeps {e['mpc_up_lqi_down']} plants up that LQI loses and loses "
        f"{e['lqi_up_mpc_down']} that LQI keeps, with the angle box {e['mpc_theta_box_up_lqi_down']} and "
        f"{e['lqi_up_mpc_theta_box_down']}"
        for e in doc["compare"].values()
    )
    grid = []
    for r in doc["rho_cap"]:
        grid.append([f"{r['rho']:g}", str(r["cap"]), *_pays_cell(r),
                     f"{r['iterations_mean']:.1f} / {r['iterations_worst']}",
                     f"{100 * r['capped_fraction_of_steps']:.0f} %", str(r["runs_needing_the_cap"])])  # fmt: skip
    ghead = ["rho", "cap", "stays up", "settling median", "IAE median", "iterations mean / worst", "steps capped"]
    ghead += ["runs that hit the cap"]
    text = table(head, rows) + "\n" + prose("Paired on the draw: " + pairs + ".") + "\n\n"
    text += "Over rho and the cap (±20 N, no angle box, the same draws):\n\n" + table(ghead, grid)
    return text + "\n" + provenance(doc) + "\n"


BLOCKS: dict[str, Callable[[], str]] = {
    "mpc_cost": mpc_cost_block,
    "mpc_pays": mpc_pays_block,
    "sched_cost": sched_cost_block,
    "sched_showcase": sched_showcase_block,
    "fixed_point_cost": fixed_point_cost_block,
    "cortex_m_targets": cortex_m_targets_block,
    "fuzz": fuzz_block,
    "soak": soak_block,
    "campaign": campaign_block,
    "loop_rates": loop_rates_block,
    "target_uart": target_uart_block,
}


# --- the pages --------------------------------------------------------------------------------------------------


def render(text: str, page: Path) -> str:
    """``text`` with every marked block rewritten; an unknown block name is an error."""

    def body(m: re.Match[str]) -> str:
        name = m["name"]
        if name not in BLOCKS:
            raise SystemExit(f"doc_figures: {page.relative_to(ROOT)} has a block {name!r} this script does not know")
        return m.group(1) + BLOCKS[name]() + m.group(4)

    return BLOCK.sub(body, text)


def check(texts: dict[Path, str], rendered: dict[Path, str]) -> list[str]:
    """One line per block that is not what it should say now, and per block missing or written twice."""
    problems, seen = [], []
    for page, text in texts.items():
        for old, new in zip(BLOCK.finditer(text), BLOCK.finditer(rendered[page])):
            seen.append(old["name"])
            if old.group(0) != new.group(0):
                problems.append(_difference(page, old["name"], old.group(0), new.group(0)))
    for name in sorted(set(BLOCKS) - set(seen)):
        problems.append(f"doc_figures: no page has the figures {name}")
    for name in sorted({n for n in seen if seen.count(n) > 1}):
        problems.append(f"doc_figures: the figures {name} are on more than one page")
    return problems


def _difference(page: Path, name: str, old: str, new: str) -> str:
    """The line saying why a block is not what it should say now, and what to do."""
    bench = SOURCE_OF.get(name, name)
    doc = result(bench)
    stale = staleness(bench, doc) if doc else None
    where = f"doc_figures: {page.relative_to(ROOT)}: the figures {name}"
    flag = "Older than the code it describes"
    if stale is not None and flag in " ".join(new.split()) and flag not in " ".join(old.split()):
        return (
            f"{where} are older than the code they describe ({stale}): record them again (scripts/bench.sh {bench}), "
            "or run scripts/doc_figures.py to say so in the docs"
        )
    return f"{where} are not what the results and the builds say now (an image size?): run scripts/doc_figures.py"


#: the benchmark a block's figures come from, where the names differ
SOURCE_OF = {"cortex_m_targets": "firmware_cost", "loop_rates": "hil_lockstep"}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", nargs="+", metavar="NAME", help="copy out/bench/NAME.json to bench/results first")
    ap.add_argument("--check", action="store_true", help="only check that the blocks say what they should now")
    args = ap.parse_args(argv)
    for name in args.record or ():
        print(f"doc_figures: recorded {record(name).relative_to(ROOT)}")
    texts = {page: page.read_text("utf-8") for page in pages()}
    rendered = {page: render(text, page) for page, text in texts.items()}
    if args.check:
        problems = check(texts, rendered)
        for line in problems:
            print(line, file=sys.stderr)
        return 1 if problems else 0
    for page, text in texts.items():
        if rendered[page] != text:
            tmp = page.with_name(f".{page.name}.tmp")
            tmp.write_text(rendered[page], "utf-8")
            os.replace(tmp, page)
            print(f"doc_figures: {page.relative_to(ROOT)} updated")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
