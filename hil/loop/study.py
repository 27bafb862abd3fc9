"""The saturation study: one spec designed with anti-windup none, clamp and backcalc, each run
through the bridge into actuator saturation, compared side by side (overshoot, recovery, windup).

The study description is a TOML file (default: the built-in ``scenarios/saturation_study.toml``):
``spec``, ``modes``, ``duration``, ``controller``, ``[plant]``, ``[transport]``, ``[initial_state]``,
optionally ``[reference]`` and ``[[disturbances]]``. Built-in: ``saturation_study`` (default: start 1 m
off the reference) and ``saturation_kick`` (a 25 N, 0.1 s push on the cart).
"""

from __future__ import annotations

import io
import json
import tempfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import ScenarioError, did_you_mean
from gainlink.fileio import parse_toml, publish_files, read_toml
from gainlink.shipping.artifact import from_dict, write

from ..paths import project_root
from .bridge import RunResult, run_scenario
from .report import plots as run_plots
from .report import report_json, summary_text
from .scenario import Scenario, parse_scenario

STUDY_KEYS = {
    "spec",
    "modes",
    "duration",
    "controller",
    "plant",
    "transport",
    "initial_state",
    "reference",
    "disturbances",
    "step_timeout",
    "description",
}
MODES = ("none", "clamp", "backcalc")


@dataclass(frozen=True)
class StudyResult:
    """Per-mode runs, the comparison table (mode -> metrics) and the text summary."""

    runs: dict[str, RunResult]
    table: dict[str, dict]
    summary: str


def default_study(name: str = "saturation_study") -> dict:
    """A built-in study description (``scenarios/<name>.toml`` of the package)."""
    path = resources.files("gainlink.hil").joinpath(f"scenarios/{name}.toml")
    if not path.is_file():
        known = ("saturation_study", "saturation_kick")
        raise ScenarioError(f"no built-in study {name!r}{did_you_mean(name, known)} ({', '.join(known)})")
    return parse_toml(path.read_text("utf-8"), what=f"built-in study {name}", error=ScenarioError)


def _load_spec(path: Path) -> dict:
    return read_toml(path, what="study: spec", error=ScenarioError)[0]


def run_saturation_study(
    *,
    report_dir: Path,
    spec_path: Path | None = None,
    controller: str | None = None,
    transport: dict | None = None,
    study: dict | None = None,
    plots: bool = True,
) -> StudyResult:
    """Design, run and compare the anti-windup modes; publish the reports into ``report_dir``.

    Parameters
    ----------
    report_dir : Path
        Output folder: ``study.json``, ``comparison.png``, ``summary.txt`` and one sub-folder per mode.
    spec_path : Path, optional
        Plant spec to design from (default: the study's ``spec``).
    controller : {"firmware", "reference"}, optional
        Overrides the study's controller.
    transport : dict, optional
        Overrides the study's python-can configuration.
    study : dict, optional
        A study description (default: :func:`default_study`).
    plots : bool
        Write the PNG plots (each mode's and ``comparison.png``); False: the JSON and text files only (the plots
        were some 40 % of a study's time).
    """
    desc = _checked_study(study)
    if spec_path is None:
        root = project_root() or Path.cwd()
        spec_path = root / desc.get("spec", "examples/pendulum.toml")
    spec = _load_spec(Path(spec_path))
    modes = _checked_modes(desc)
    runs: dict[str, RunResult] = {}
    artifacts: dict[str, Any] = {}
    files: dict[str, bytes | str] = {}
    with tempfile.TemporaryDirectory(prefix="gainlink-study-") as tmp:
        for mode in modes:
            gains = _design_mode(spec, mode=mode, spec_path=spec_path, folder=Path(tmp) / mode)
            artifacts[mode] = from_dict(json.loads(gains.read_text()))
            scenario = _mode_scenario(desc, mode=mode, gains=gains, controller=controller, transport=transport)
            runs[mode] = run_scenario(scenario, artifact=artifacts[mode])
            files.update(_mode_files(runs[mode], mode=mode, gains=gains, plots=plots))
    table = {mode: _row(r) for mode, r in runs.items()}
    summary = _summary(table, report_dir=report_dir)
    files["study.json"] = _study_json(table, desc=desc, spec_path=spec_path)
    if plots:
        files["comparison.png"] = _comparison_png(runs, artifacts)
    files["summary.txt"] = summary
    publish_files(report_dir, files)
    return StudyResult(runs=runs, table=table, summary=summary)


def _checked_study(study: dict | None) -> dict:
    """A copy of the study description (the default one when none is given), its keys checked."""
    desc = dict(study or default_study())
    unknown = sorted(set(desc) - STUDY_KEYS)
    if unknown:
        raise ScenarioError(f"study: unknown key(s) {', '.join(unknown)}")
    return desc


def _checked_modes(desc: dict) -> list[str]:
    """The study's anti-windup modes (all of :data:`MODES` by default), checked."""
    modes = list(desc.get("modes", MODES))
    bad = [m for m in modes if m not in MODES]
    if bad:
        raise ScenarioError(f"study: unknown anti-windup mode(s) {', '.join(bad)}")
    return modes


def _design_mode(spec: dict, *, mode: str, spec_path: Path, folder: Path) -> Path:
    """Design ``spec`` with anti-windup ``mode`` and write the sealed artifact to ``folder/gains.json``."""
    from gainlink.laws import design
    from gainlink.spec import parse_spec

    data = json.loads(json.dumps(spec))
    data.setdefault("limits", {})["anti_windup"] = mode
    data["name"] = f"{spec.get('name', 'plant')}_{mode}"[:32]
    sealed = design(parse_spec(data, source=f"{spec_path} (anti_windup={mode})")).artifact
    gains = folder / "gains.json"
    gains.parent.mkdir()
    write(gains, sealed)
    return gains


def _mode_scenario(desc: dict, *, mode: str, gains: Path, controller: str | None, transport: dict | None) -> Scenario:
    """The lockstep scenario that runs one mode's artifact as the study describes."""
    return parse_scenario(
        {
            "name": f"saturation_{mode}",
            "artifact": str(gains),
            "duration": desc.get("duration", 12.0),
            "mode": "lockstep",
            "controller": controller or desc.get("controller", "firmware"),
            "step_timeout": desc.get("step_timeout", 1.0),
            "plant": desc["plant"],
            "transport": transport or desc["transport"],
            "initial_state": desc.get("initial_state", {}),
            "reference": desc.get("reference", {}),
            "disturbances": desc.get("disturbances", []),
        }
    )


def _mode_files(result: RunResult, *, mode: str, gains: Path, plots: bool) -> dict[str, bytes | str]:
    """One mode's report files (artifact, report.json, summary, and with ``plots`` its PNGs) by their path in the
    report folder."""
    files: dict[str, bytes | str] = {
        f"{mode}/gains.json": gains.read_text(),
        f"{mode}/report.json": report_json(result),
        f"{mode}/summary.txt": summary_text(result),
    }
    for name, png in (run_plots(result) if plots else {}).items():
        files[f"{mode}/{name}"] = png
    return files


def _study_json(table: dict, *, desc: dict, spec_path: Path) -> str:
    """``study.json``: the comparison table, the initial state and the spec it was designed from."""
    doc = {"modes": table, "initial_state": desc.get("initial_state", {}), "spec": str(spec_path)}
    return json.dumps(doc, sort_keys=True, indent=2, allow_nan=False) + "\n"


def _row(r: RunResult) -> dict:
    m = r.metrics
    tracked = next(iter(m["tracked"].values()), {})
    return {
        "complete": m["complete"],
        "overshoot_pct": tracked.get("overshoot_pct"),
        "settling_time_s": tracked.get("settling_time_s"),
        "iae": tracked.get("iae"),
        "saturation_fraction": m["saturation_fraction"],
        "saturated_fraction_any": m["saturated_steps"] / m["steps"] if m["steps"] else 0.0,
        "peak_integrator": m.get("peak_integrator", {}),
        "inputs_peak_abs": m["inputs_peak_abs"],
        "outputs_peak_abs": m["outputs_peak_abs"],
        "outputs_final": m["outputs_final"],
        "lost": m["lost"],
    }


def _fmt(v: Any, unit: str = "") -> str:
    return "n/a" if v is None else f"{v:.3g}{unit}"


def _summary(table: dict, *, report_dir: Path) -> str:
    outputs = list(next(iter(table.values()))["outputs_peak_abs"]) if table else []
    lines = [
        "Saturation study: anti-windup none vs clamp vs backcalc",
        f"  {'mode':<9} {'overshoot':>10} {'settling':>10} {'IAE':>8} {'saturated':>10} {'peak |z|':>9}"
        + "".join(f" {'peak |' + o + '|':>12}" for o in outputs),
    ]
    for mode, row in table.items():
        sat = row["saturated_fraction_any"]  # steps in which any input saturated
        z = max(row["peak_integrator"].values()) if row["peak_integrator"] else None
        lines.append(
            f"  {mode:<9} {_fmt(row['overshoot_pct'], '%'):>10} {_fmt(row['settling_time_s'], ' s'):>10} "
            f"{_fmt(row['iae']):>8} {100 * sat:>9.1f}% {_fmt(z):>9}"
            + "".join(f" {_fmt(row['outputs_peak_abs'][o]):>12}" for o in outputs)
            + ("" if row["complete"] else "  (incomplete)")
        )
    for label, key in (("overshoot", "overshoot_pct"), ("settling time", "settling_time_s"), ("IAE", "iae")):
        ranked = [(row[key], mode) for mode, row in table.items() if row[key] is not None and row["complete"]]
        if ranked:
            lines.append(f"  lowest {label}: {min(ranked)[1]}")
    lines.append(f"  report: {report_dir / 'study.json'}")
    return "\n".join(lines) + "\n"


def _comparison_png(runs: dict[str, RunResult], artifacts: dict[str, Any]) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first = next(iter(artifacts.values()))
    j = int(np.argmax(np.abs(first.Ci[0]))) if first.q else 0
    name = first.signals["outputs"][j]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for mode, r in runs.items():
        ax1.plot(r.trace.t, r.trace.y[:, j], label=mode)
        ax2.plot(r.trace.t, r.trace.u[:, 0], label=mode)
    ax1.set_ylabel(name)
    ax1.axhline(0.0, color="k", lw=0.5)
    ax2.set_ylabel(first.signals["inputs"][0])
    ax2.axhline(first.u_max[0], color="r", lw=0.8, ls="--")
    ax2.axhline(first.u_min[0], color="r", lw=0.8, ls="--")
    ax2.set_xlabel("t [s]")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Saturation study: anti-windup modes")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()
