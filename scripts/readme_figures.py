"""README figures from the benchmarks' JSON: never typed in by hand.

README.md holds marked blocks, ``<!-- figures:NAME -->`` ... ``<!-- /figures:NAME -->``; this script writes each
block from the recorded results in ``bench/results/*.json`` (committed: the measurements the README shows).

    .venv/bin/python scripts/readme_figures.py                 rewrite the blocks from bench/results/
    .venv/bin/python scripts/readme_figures.py --record NAME   first copy out/bench/NAME.json (a fresh `make bench`)
                                                              into bench/results/ with when and where it ran
    .venv/bin/python scripts/readme_figures.py --check         exit 1 if a block differs from what the results say

``scripts/bench.sh`` (``make bench``, ``make bench-fuzz``, ``make bench-soak``) records every benchmark that
succeeded; the test suite runs ``--check``. A result whose ``recorded`` entry says ``from`` README was carried over
from figures typed in before this script existed (its JSON was not kept); the block says so.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "bench" / "results"
OUT = ROOT / "out" / "bench"
BLOCK = re.compile(r"(<!-- figures:(?P<name>[a-z_]+) -->\n)(?P<body>.*?)(<!-- /figures:(?P=name) -->)", re.S)

Doc = dict[str, Any]


# --- reading and recording --------------------------------------------------------------------------------------


def result(name: str) -> Doc | None:
    """bench/results/NAME.json, or None when that benchmark was never recorded."""
    path = RESULTS / f"{name}.json"
    return json.loads(path.read_text("utf-8")) if path.is_file() else None


def record(name: str) -> Path:
    """Copy out/bench/NAME.json to bench/results/NAME.json, stamped with the date and the machine's load."""
    src = OUT / f"{name}.json"
    doc = json.loads(src.read_text("utf-8"))
    stamp = {
        "from": f"bench/{name}.py",
        "date": datetime.date.today().isoformat(),
        "cpus": os.cpu_count(),
        "load_average_at_record": round(os.getloadavg()[0], 2),
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    dst = RESULTS / f"{name}.json"
    tmp = dst.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"recorded": stamp, **doc}, indent=2) + "\n", "utf-8")
    os.replace(tmp, dst)
    return dst


def prose(text: str, indent: str = "") -> str:
    """``text`` wrapped at the README's 120 columns (continuation lines indented by ``indent``)."""
    return "\n".join(textwrap.wrap(text, 120, subsequent_indent=indent, break_on_hyphens=False))


def provenance(doc: Doc) -> str:
    """A sentence saying where a result comes from."""
    rec = doc.get("recorded", {})
    if "README" in rec.get("from", ""):
        return prose(
            f"Recorded result carried over from the README (its JSON was not kept): {rec.get('conditions', '')}."
        )
    load = run_load(doc)
    if load is not None:
        where = f"{rec.get('cpus', '?')} CPUs; the benchmark saw a load average of {load:.1f}"
    else:
        where = f"{rec.get('cpus', '?')} CPUs, load average {rec.get('load_average_at_record', 0):g} when recorded"
    return prose(f"`{rec.get('from', '?')}`, recorded {rec.get('date', '?')} ({where}).")


def run_load(doc: Doc) -> float | None:
    """The 1-minute load average a benchmark wrote into its own JSON (each names it its own way), if any."""
    for key in ("load_average_1min", "load_avg_1min", "load_average_before"):
        value = doc.get(key)
        if value is not None:
            return float(value[0] if isinstance(value, list) else value)
    return None


def missing(what: str, target: str) -> str:
    return f"No {what} recorded yet: `{target}` measures it.\n"


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
    return "\n".join(prose(line, "  ") for line in lines) + "\n\n" + provenance(doc) + "\n"


def loop_rates_block() -> str:
    rows = []
    lock = result("hil_lockstep")
    if lock is not None:
        base = lock["baseline"]["steps_per_s"]
        for key, label in (
            ("can_fd", "CAN FD, bridge and firmware sharing a CPU (default)"),
            ("can_fd_unpinned", "CAN FD, placement left to the kernel"),
            ("classic_can", "classic CAN (3 + 1 frames a step)"),
            ("can_fd_busy_poll", "CAN FD, busy polling"),
        ):
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
    return table(["loop", "steps/s", "against the baseline"], rows) + "\n" + "\n".join(map(provenance, sources)) + "\n"


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
        q, f = r["q31_image"], r["float32_image"]
        rows.append(
            [
                f"{r['target']} ({r['board']})",
                num(r["q31_instructions_per_step"]),
                num(r["float32_instructions_per_step"]),
                "—" if plain is None else num(plain),
                ratio,
                f"{num(q['flash_bytes'])} / {num(f['flash_bytes'])} B",
                f"{num(q['ram_bytes_without_stack'])} / {num(f['ram_bytes_without_stack'])} B",
            ]
        )
    head = ["core (board)", "q31", "float32 as built", "float32 plain multiply-add", "float32 / q31"]
    head += ["flash q31 / float32 image", "RAM (no stack) q31 / float32 image"]
    return table(head, rows) + "\n" + provenance(doc) + "\n"


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


BLOCKS: dict[str, Callable[[], str]] = {
    "sched_cost": sched_cost_block,
    "sched_showcase": sched_showcase_block,
    "fixed_point_cost": fixed_point_cost_block,
    "fuzz": fuzz_block,
    "soak": soak_block,
    "campaign": campaign_block,
    "loop_rates": loop_rates_block,
    "target_uart": target_uart_block,
}


# --- the README -------------------------------------------------------------------------------------------------


def render(text: str) -> str:
    """``text`` with every marked block rewritten; an unknown block name is an error."""

    def body(m: re.Match[str]) -> str:
        name = m["name"]
        if name not in BLOCKS:
            raise SystemExit(f"readme_figures: README.md has a block {name!r} this script does not know")
        return m.group(1) + BLOCKS[name]() + m.group(4)

    return BLOCK.sub(body, text)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", nargs="+", metavar="NAME", help="copy out/bench/NAME.json to bench/results first")
    ap.add_argument("--check", action="store_true", help="only check that README.md's blocks are up to date")
    args = ap.parse_args(argv)
    for name in args.record or ():
        print(f"readme_figures: recorded {record(name).relative_to(ROOT)}")
    text = README.read_text("utf-8")
    new = render(text)
    found = {m["name"] for m in BLOCK.finditer(text)}
    if args.check:
        stale = [m["name"] for m, n in zip(BLOCK.finditer(text), BLOCK.finditer(new)) if m.group(0) != n.group(0)]
        if stale or found != set(BLOCKS):
            absent = sorted(set(BLOCKS) - found)
            print(f"readme_figures: stale blocks {stale}, missing blocks {absent}: run scripts/readme_figures.py")
            return 1
        return 0
    if new != text:
        tmp = README.with_suffix(".md.tmp")
        tmp.write_text(new, "utf-8")
        os.replace(tmp, README)
        print("readme_figures: README.md updated")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
