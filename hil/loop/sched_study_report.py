"""The showcase's summary and comparison plot (:mod:`.sched_study`): per design, tracking over the sweep,
damping of each step and both twins, from the same numbers ``report.json`` holds."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def _f(v: Any, unit: str = "") -> str:
    return "n/a" if v is None else f"{v:.3g}{unit}"


def showcase_summary(doc: dict, *, report_dir: Path) -> str:
    """``summary.txt``: one line per design and its steps, then what the scheduled design changed."""
    designs = doc["designs"]
    steps = list(doc["steps"])
    lines = [
        f"Scheduled showcase: {doc['spec']} scheduled vs its single point {doc['single_point']:g}",
        f"  {'design':<10} {'sweep IAE':>10} {'max |e|':>9} {'held |e|':>9} {'model twin':>11} {'C vs twin du':>13}"
        + "".join(f" {'step ' + s + ' overshoot':>20} {'settling':>9}" for s in steps),
    ]
    for name, row in designs.items():
        per_step = [(_f(row["step_" + s]["overshoot_pct"], "%"), _f(row["step_" + s]["settling_time_s"], " s"))
                    for s in steps]  # fmt: skip
        lines.append(
            f"  {name:<10} {_f(row['sweep_iae']):>10} {_f(row['sweep_max_abs_e'], ' m'):>9} "
            f"{_f(row['sweep_hold_max_abs_e'], ' m'):>9} "
            f"{_f(row['model_twin_worst']):>11} {_f(row['twin_worst_du_rel']):>13}"
            + "".join(f" {over:>20} {settle:>9}" for over, settle in per_step)
            + ("" if row["complete"] else "  (incomplete)")
        )
    single, sched = designs["single"], designs["scheduled"]
    lines.append(
        f"  scheduled / single: sweep IAE {_f(sched['sweep_iae'] / single['sweep_iae'])}, max |e| "
        f"{_f(sched['sweep_max_abs_e'] / single['sweep_max_abs_e'])}"
    )
    lines.append(f"  report: {report_dir / 'report.json'}")
    return "\n".join(lines) + "\n"


def comparison_png(runs: dict[str, dict[str, Any]], desc: dict) -> bytes:
    """``comparison.png``: the level against its reference for each design, the sweep and each step."""
    import matplotlib.pyplot as plt
    from gainlink.proof.twin_plot import png_bytes

    names = ["sweep"] + [f"step_{s}" for s in desc["steps"]]
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.4 * len(names)), squeeze=False)
    for ax, name in zip(axes[:, 0], names):
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
