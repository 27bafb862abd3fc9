"""The run report: ``report.json``, PNG plots (matplotlib Agg), a one-screen text summary."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.fileio import publish_files
from gainlink.laws import flags, law_of
from gainlink.proof.twin_plot import png_bytes, twin_difference_figure

from .bridge import RunResult


def report_json(result: RunResult) -> str:
    """The text of ``report.json``: metrics, what ran, and the scenario (sorted keys, no timestamps)."""
    sc = result.scenario
    body = dict(result.metrics)
    body["scenario"] = {
        "name": sc.name,
        "duration": sc.duration,
        "mode": sc.mode,
        "controller": sc.controller,
        "faults": [f.__dict__ for f in sc.faults],
        "seed": sc.seed,
    }
    body["run"] = result.info
    return json.dumps(body, sort_keys=True, indent=2, allow_nan=False) + "\n"


def unit_of(units: dict | None, name: str) -> str:
    """`` unit`` of signal ``name`` (a reference ``r_<output>``: its output's), ``""`` without one."""
    units = units or {}
    unit = units.get(name) or (units.get(name[2:]) if name.startswith("r_") else None)
    return f" {unit}" if unit else ""


def _integral_unit(units: dict | None, name: str) -> str:
    """`` unit time`` of an integral of signal ``name`` (an integrator, an IAE), ``""`` without a unit."""
    unit = unit_of(units, name)
    return f"{unit} {(units or {}).get('time', 's')}" if unit else ""


def _fmt(v: Any, unit: str = "", digits: int = 4) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.{digits}g}{unit}"
    return f"{v}{unit}"


def summary_text(result: RunResult, *, report_dir: Path | None = None) -> str:
    """A one-screen summary of a run."""
    m = result.metrics
    lines = [
        f"HIL run {result.scenario.name}: {'complete' if m['complete'] else 'INCOMPLETE'}"
        + (f" ({m['reason']})" if m.get("reason") else "")
    ]
    info = result.info
    lines.append(
        f"  artifact {info['artifact']['name']} sha256:{info['artifact']['sha256'][:16]}  plant "
        f"{info['plant']['name']}  controller {info['controller']['kind']}  transport "
        f"{info['transport'].get('config', {}).get('interface', info['transport'].get('kind'))}"
    )
    lines += _plant_lines(info, mode=m["mode"])
    comp = info["artifact"].get("compensator")
    if comp:
        lines.append(
            f"  {comp['summary']}"
            + ("" if comp["stable"] else ": run it only with the loop closed; a broken sensor path lets it run away")
        )
    lines.append(
        f"  mode {m['mode']}: {m['steps']}/{m['steps_planned']} steps in {m['wall_s']:.2f} s "
        f"({_fmt(m['steps_per_s'], '/s', 5)}), SCHED_FIFO {'on' if m['sched_fifo'] else 'off'}"
        + (f", PM QoS {'on' if m['pm_qos'] else 'off'}" if "pm_qos" in m else "")
        + (f", CPUs {m['cpu']['placement']}" if m.get("cpu") else "")
    )
    lat, jit = m["latency_us"], m["period_jitter_us"]
    lines.append(
        f"  latency us p50 {_fmt(lat['p50'])} p99 {_fmt(lat['p99'])} max {_fmt(lat['max'])};  "
        f"period jitter us p50 {_fmt(jit['p50'])} p99 {_fmt(jit['p99'])} max {_fmt(jit['max'])}"
    )
    overruns = f" (overruns {m['overruns']}, {m['overrun_policy']})" if "overruns" in m else ""
    lines.append(
        f"  lost {m['lost']}  late {m['late']}  deadline misses {m['deadline_misses']}{overruns}  "
        f"faults injected {', '.join(f'{k} {v}' for k, v in m['faults_injected'].items() if v) or 'none'}"
    )
    if "uart" in m:
        lines += _uart_lines(m["uart"], board=info["controller"].get("board"))
    units = info["artifact"].get("units")
    time_unit = f" {(units or {}).get('time', 's')}"
    lines.append(_saturation_line(m))
    if "peak_integrator" in m:
        lines.append(
            "  peak integrator: "
            + ", ".join(f"{k} {_fmt(v, _integral_unit(units, k))}" for k, v in m["peak_integrator"].items())
        )
    lines += twin_lines(m.get("twin"), units=units)
    lines += model_lines(m.get("model_twin"), units=units)
    lines += law_of(result.artifact).report_lines(m)
    for name, tr in m["tracked"].items():
        lines.append(
            f"  {name}: overshoot {_fmt(tr['overshoot_pct'], '%')}, settling {_fmt(tr['settling_time_s'], time_unit)}"
            f", IAE {_fmt(tr['iae'], _integral_unit(units, name))}"
        )
    lines.append(
        "  final outputs: " + ", ".join(f"{k} {_fmt(v, unit_of(units, k))}" for k, v in m["outputs_final"].items())
    )
    if report_dir is not None:
        lines.append(f"  report: {report_dir / 'report.json'}")
    return "\n".join(lines) + "\n"


def _uart_lines(u: dict, *, board: str | None) -> list[str]:
    """What the emulated UART sustained, from the service time of every answered sample (late ones too)."""
    svc = u["service_us"]
    return [
        f"  emulated UART ({board}): a loop up to {_fmt(u['loop_hz_p99'], ' Hz', 4)} covers the p99 service time "
        f"({_fmt(svc['p99'], ' us')}; p50 {_fmt(svc['p50'], ' us')}), {_fmt(u['round_trips_per_s'], '', 4)} "
        "round trips/s back to back",
        f"    service time = command back minus the later of its sample's send and the previous command, over "
        f"{u['answered']} answered samples ({u['late_answers']} late); {u['unanswered']} never answered",
    ]


def _saturation_line(m: dict) -> str:
    """Steps in which any input saturated, of all steps; then each input's own count."""
    per_input = m["saturated_steps_per_input"]
    steps = max(m["steps"], 1)
    return f"  saturated {m['saturated_steps']} of {m['steps']} steps (any input); per input: " + ", ".join(
        f"{k} {v} ({100 * v / steps:.1f}%)" for k, v in per_input.items()
    )


def _plant_lines(info: dict, *, mode: str) -> list[str]:
    """Which interface of an FMU ran and why, against the one the design's model was checked through."""
    plant, model = info["plant"], info["artifact"].get("model", {})
    if "interface" not in plant:
        return []
    out = [f"  plant interface {plant['interface']}: {plant['interface_reason']}"]
    checked = model.get("plant_interface", "")
    if checked and not checked.startswith(plant["interface"] + ":"):
        out.append(
            f"  WARNING: the design's model was checked through {checked.split(':')[0]}, this run used "
            f"{plant['interface']}: compare the model twin below"
        )
    if mode == "realtime" and plant["interface"] == "me":
        out.append("  Model Exchange (CVode) costs ~30x a Co-Simulation step: check the deadline misses below")
    return out


def twin_lines(tw: dict | None, *, units: dict | None = None) -> list[str]:
    """The twin comparison in a few lines: what the implementation cost against the ideal loop (each figure with
    its signal's unit, from ``units``: the artifact's ``signals.units``)."""
    if not tw:
        return []
    out = [
        "  against the float64 twin (same plant, noise, references, disturbances; ideal law, no link):",
        "    max |u - u_twin|: "
        + ", ".join(
            f"{k} {_fmt(v['max_du'], unit_of(units, k))} ({_fmt(v['max_du_rel'], digits=3)} of span)"
            for k, v in tw["inputs"].items()
        ),
        "    max |y - y_twin|: "
        + ", ".join(
            f"{k} {_fmt(v['max_dy'], unit_of(units, k))} ({_fmt(v['max_dy_rel'], digits=3)} of range)"
            for k, v in tw["outputs"].items()
        ),
    ]
    out.append(
        "    IAE real vs twin: "
        + ", ".join(
            f"{k} {_fmt(v['real'], _integral_unit(units, k))} vs {_fmt(v['twin'])} "
            f"({'+' if (v['difference_rel'] or 0) >= 0 else ''}"
            f"{_fmt(None if v['difference_rel'] is None else 100 * v['difference_rel'], '%', 3)})"
            for k, v in tw["iae"].items()
        )
    )
    return out


def model_lines(mt: dict | None, *, units: dict | None = None) -> list[str]:
    """The model twin in a few lines: how far the plant departs from the design's own linear model."""
    if not mt:
        return []
    worst = mt["worst"]
    out = [
        f"  against the model twin (the same law around the design's linear model, from {mt['start']}):",
        "    max |y - y_model|: "
        + ", ".join(
            f"{k} {_fmt(v['max_dy'], unit_of(units, k))} ({_fmt(v['max_dy_rel'], digits=3)} of range)"
            for k, v in mt["outputs"].items()
        ),
        "    IAE plant / model: "
        + ", ".join(
            f"{k} {_fmt(v['plant'])} / {_fmt(v['model'])} = {_fmt(v['ratio'], digits=3)}" for k, v in mt["iae"].items()
        ),
    ]
    if mt["warning"]:
        out.append(
            f"  WARNING: the plant departs from the design's model by {_fmt(worst, digits=3)} of an output's range "
            f"(threshold {mt['threshold']:g}): the design's predictions do not hold for this plant"
        )
    return out


def has_sigma(result: RunResult) -> bool:
    """Whether the run's law reported a sigma (its trace then has ``sigma.csv`` and ``sigma.png``)."""
    return bool(np.isfinite(result.trace.sigma).any())


def sigma_csv(trace: Any) -> str:
    """``t,sigma,held,clipped,rate`` per step: the sigma the law used and its flags (0/1)."""
    bits = np.asarray(trace.flags, dtype=np.int64)
    rows = ["t,sigma,held,clipped,rate"]
    for t, s, f in zip(trace.t, trace.sigma, bits):
        rows.append(f"{t:.9g},{s:.9g},{int(bool(f & flags.SIGMA_HELD))},{int(bool(f & flags.SIGMA_CLIPPED))},"
                    f"{int(bool(f & flags.SIGMA_RATE))}")  # fmt: skip
    return "\n".join(rows) + "\n"


def sigma_plot(result: RunResult) -> bytes:
    """``sigma.png``: sigma against time, the law's points (its ``schedule`` block) as lines, flagged steps marked."""
    import matplotlib.pyplot as plt

    tr, sch = result.trace, result.metrics.get("schedule") or {}
    fig, ax = plt.subplots(figsize=(8, 2.6))
    ax.plot(tr.t, tr.sigma, label=f"sigma ({sch.get('sigma', '')})")
    for v in sch.get("points", []):
        ax.axhline(v, color="0.6", lw=0.7, ls=":")
    flagged = (np.asarray(tr.flags) & (flags.SIGMA_HELD | flags.SIGMA_CLIPPED | flags.SIGMA_RATE)) != 0
    if flagged.any():
        ax.plot(tr.t[flagged], tr.sigma[flagged], "r.", ms=3, label="held / clipped / rate-limited")
    ax.set_xlabel("t [s]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"{result.scenario.name}: scheduling variable")
    return png_bytes(fig)


def plots(result: RunResult) -> dict[str, bytes]:
    """PNG plots: outputs with references, inputs with limits, latency histogram."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tr, artifact = result.trace, result.artifact
    outs = result.info["plant"]["outputs"]
    ins = result.info["plant"]["inputs"]
    files = {}
    fig, axes = plt.subplots(len(outs), 1, figsize=(8, 2.2 * len(outs)), sharex=True, squeeze=False)
    for i, name in enumerate(outs):
        ax = axes[i, 0]
        ax.plot(tr.t, tr.y[:, i], label=name)
        if tr.has_twin:
            ax.plot(tr.t, tr.twin_y[:, i], "--", lw=0.9, label=f"{name} (float64 twin)")
        if artifact is not None and artifact.q:
            for j, rname in enumerate(artifact.signals["references"]):
                if artifact.Ci[j, i] != 0:
                    ax.plot(tr.t, tr.r[:, j], "--", label=f"reference {rname}")
        ax.set_ylabel(_label(artifact, name))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel(_time_label(artifact))
    fig.suptitle(f"{result.scenario.name}: outputs")
    files["outputs.png"] = png_bytes(fig)
    fig, axes = plt.subplots(len(ins), 1, figsize=(8, 2.2 * len(ins)), sharex=True, squeeze=False)
    for i, name in enumerate(ins):
        ax = axes[i, 0]
        ax.plot(tr.t, tr.u[:, i], label=f"{name} (controller)")
        if tr.has_twin:
            ax.plot(tr.t, tr.twin_u[:, i], "--", lw=0.9, label=f"{name} (float64 twin)")
        if artifact is not None:
            ax.axhline(artifact.u_min[i], color="r", lw=0.8, ls="--", label="limits")
            ax.axhline(artifact.u_max[i], color="r", lw=0.8, ls="--")
        ax.set_ylabel(_label(artifact, name))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel(_time_label(artifact))
    fig.suptitle(f"{result.scenario.name}: inputs")
    files["inputs.png"] = png_bytes(fig)
    fig, ax = plt.subplots(figsize=(8, 3))
    lat = tr.latency_ns[np.isfinite(tr.latency_ns)] / 1e3
    if lat.size:
        ax.hist(lat, bins=60)
    ax.set_xlabel("round-trip latency [us]")
    ax.set_ylabel("steps")
    ax.set_yscale("log")
    ax.set_title(f"{result.scenario.name}: latency ({lat.size} commands)")
    files["latency.png"] = png_bytes(fig)
    if tr.has_twin:
        files["twin.png"] = _twin_plot(result, outs=outs, ins=ins, artifact=artifact)
    if tr.has_model_twin:
        files["model_twin.png"] = _model_twin_plot(result, outs=outs, artifact=artifact)
    return files


def _model_twin_plot(result: RunResult, *, outs: list[str], artifact: Any) -> bytes:
    """Per output: the plant, the model twin and the closed-loop twin, with the references it tracks."""
    import matplotlib.pyplot as plt

    tr = result.trace
    fig, axes = plt.subplots(len(outs), 1, figsize=(8, 2.4 * len(outs)), sharex=True, squeeze=False)
    for i, name in enumerate(outs):
        ax = axes[i, 0]
        ax.plot(tr.t, tr.y[:, i], lw=1.2, label=f"{name} (plant)")
        ax.plot(tr.t, tr.model_y[:, i], "--", lw=1.0, label=f"{name} (model twin: the design's linear model)")
        if tr.has_twin:
            ax.plot(tr.t, tr.twin_y[:, i], ":", lw=1.0, label=f"{name} (closed-loop twin: the plant, ideal law)")
        if artifact is not None and artifact.q:
            for j, rname in enumerate(artifact.signals["references"]):
                if artifact.Ci[j, i] != 0:
                    ax.plot(tr.t, tr.r[:, j], color="0.5", lw=0.8, label=f"reference {rname}")
        ax.set_ylabel(_label(artifact, name))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=7)
    axes[-1, 0].set_xlabel(_time_label(artifact))
    mt = result.metrics.get("model_twin") or {}
    worst = mt.get("worst")
    fig.suptitle(
        f"{result.scenario.name}: plant, model twin and closed-loop twin"
        + (f" (mismatch {worst:.3g} of range)" if worst is not None else "")
    )
    return png_bytes(fig)


def _label(artifact: Any, name: str) -> str:
    """``name [unit]`` when the artifact gives the signal a unit (and is at hand), else ``name``."""
    return name if artifact is None else artifact.label(name)


def _time_label(artifact: Any) -> str:
    return f"t [{'s' if artifact is None else artifact.unit('time')}]"


def _twin_plot(result: RunResult, *, outs: list[str], ins: list[str], artifact: Any = None) -> bytes:
    """The run minus its twin, per output and input: what the implementation cost, over time."""
    tr = result.trace
    fig = twin_difference_figure(
        tr.t,
        y=tr.y,
        twin_y=tr.twin_y,
        u=tr.u,
        twin_u=tr.twin_u,
        outputs=outs,
        inputs=ins,
        title=result.scenario.name,
        marked=~tr.got,
        marked_label="no command in time",
        units=None if artifact is None else artifact.signals.get("units"),
        time_unit="s" if artifact is None else artifact.unit("time"),
    )
    return png_bytes(fig)


def write_report(result: RunResult, report_dir: str | Path, *, with_plots: bool = True) -> Path:
    """Compute every report file, then publish them atomically into ``report_dir``."""
    report_dir = Path(report_dir)
    files: dict[str, bytes | str] = {"report.json": report_json(result)}
    if with_plots:
        files.update(plots(result))
    if has_sigma(result):  # a law with a scheduling variable: sigma per step
        files["sigma.csv"] = sigma_csv(result.trace)
        if with_plots:
            files["sigma.png"] = sigma_plot(result)
    files["summary.txt"] = summary_text(result, report_dir=report_dir)
    publish_files(report_dir, files)
    return report_dir / "report.json"
