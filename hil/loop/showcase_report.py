"""The showcase's summary and comparison plot (:mod:`.showcase`): per design, tracking over the sweep,
damping of each step and both twins, from the same numbers ``report.json`` holds."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any


def _f(v: Any, unit: str = "") -> str:
    return "n/a" if v is None else f"{v:.3g}{unit}"


def _settling(step: dict) -> str:
    return _f(step["settling_time_s"], " s") if step["settled"] else "not settled"


def _table(rows: list[list[str]]) -> list[str]:
    """Columns right-aligned to their widest cell (the first left-aligned), two spaces apart."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return [
        "  " + "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths))).rstrip()
        for r in rows
    ]


def showcase_summary(doc: dict, *, report_dir: Path) -> str:
    """``summary.txt``: one line per design and its steps (every figure with its unit), what the first seconds of
    each run were (the laws' start, before the references move), then what the scheduled design changed."""
    designs = doc["designs"]
    steps = list(doc["steps"])
    head = ["design", "sweep IAE", "max |e|", "held |e|", "model twin", "C vs twin du"]
    head += [c for s in steps for c in (f"step {s} overshoot", "settling")] + ["start |e|"]
    rows = [head]
    for name, row in designs.items():
        rows.append(
            [
                name + ("" if row["complete"] else " (incomplete)"),
                _f(row["sweep_iae"], " m s"),
                _f(row["sweep_max_abs_e"], " m"),
                _f(row["sweep_hold_max_abs_e"], " m"),
                _f(row["model_twin_worst"], " of range"),
                _f(row["twin_worst_du_rel"], " of span"),
                *[c for s in steps for c in (_f(row["step_" + s]["overshoot_pct"], " %"), _settling(row["step_" + s]))],
                _f(row.get("start_max_abs_e"), " m"),
            ]
        )
    lines = [
        f"Scheduled showcase: {doc['spec']} scheduled vs its single point {doc['single_point']:g} m",
        *_table(rows),
    ]
    lines += _notes(doc, steps)
    single, sched = designs["single"], designs["scheduled"]
    lines.append(
        f"  scheduled / single: sweep IAE {_f(sched['sweep_iae'] / single['sweep_iae'])}, max |e| "
        f"{_f(sched['sweep_max_abs_e'] / single['sweep_max_abs_e'])}"
    )
    lines.append(f"  report: {report_dir / 'report.json'}")
    return "\n".join(lines) + "\n"


def _notes(doc: dict, steps: list[str]) -> list[str]:
    """What the columns count from, what "not settled" and "start |e|" mean, and where each design's start was
    worst (the first seconds of each run, which comparison.png shows and the other columns leave out)."""
    starts = {float(doc["sweep"]["start"])} | {float(doc["steps"][s]["at"]) for s in steps}
    when = f"the first {starts.pop():g} s of each run" if len(starts) == 1 else "each run before its reference moves"
    worst = ", ".join(
        f"{name} {_f(row.get('start_max_abs_e'), ' m')} (in {row.get('start_worst_run', 'n/a')})"
        for name, row in doc["designs"].items()
    )
    notes = [
        f"start |e|: the largest |r - h| in {when}, before the sweep and the steps begin, while each law starts from "
        "rest at the plant's trim (the single-point law from its own point's trim command, the scheduled law from "
        f"the trim at the level it measures): {worst}. The other columns count from there.",
        "settling: the last exit from 5 % of the step; not settled: outside that band within the last quarter of the "
        "run after the step (the level has not stayed there).",
    ]
    return [textwrap.fill(n, width=118, initial_indent="  ", subsequent_indent="    ") for n in notes]


def comparison_png(runs: dict[str, dict[str, Any]], desc: dict) -> bytes:
    """``comparison.png``: the level against its reference for each design, the sweep and each step."""
    import matplotlib.pyplot as plt
    from gainlink.proof.twin_plot import png_bytes

    names = ["sweep"] + [f"step_{s}" for s in desc["steps"]]
    starts = [desc["sweep"]["start"]] + [desc["steps"][s]["at"] for s in desc["steps"]]
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.4 * len(names)), squeeze=False)
    for ax, name, start in zip(axes[:, 0], names, starts):
        ax.axvspan(0.0, start, color="0.92", lw=0, label="the laws' start (not compared)")
        first = next(iter(runs.values()))[name]
        ax.plot(first.trace.t, first.trace.r[:, 0], "k--", lw=0.8, label="reference")
        for design, per in runs.items():
            ax.plot(per[name].trace.t, per[name].trace.y[:, 0], label=design)
        ax.set_ylabel(f"h [m] ({name})")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle("Scheduled showcase: single-point vs scheduled design")
    return png_bytes(fig)
