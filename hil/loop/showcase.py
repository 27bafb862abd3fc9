"""The scheduled-law showcase: a scheduled spec designed as scheduled and as one unscheduled design at a single
point, both run side by side across the whole envelope (a reference sweep, and a step at each end) against the
same nonlinear plant, with both twins; compared on tracking (IAE and max |e| over the sweep) and damping
(overshoot and settling time of the steps).

The description is a TOML file (default: the built-in ``scenarios/tank_showcase.toml``): ``spec``,
``single_point``, ``controller``, ``[plant]``, ``[sweep]`` (``low``, ``high``, ``rate``, ``start``, ``duration``),
``[steps.NAME]`` (``from``, ``to``, ``at``, ``duration``), ``[transport]`` and ``step_timeout`` (s each lockstep
step waits for the node's command, default 1). Every run goes through the one dispatcher
(:func:`~.bridge.run_scenario`): with a ``[transport]`` hardware in the loop (``controller = "firmware"``: the
firmware's node for the link, on each design's law; ``"reference"``: the Python reference node), without one
software in the loop in process.
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import ScenarioError, did_you_mean
from gainlink.fileio import parse_toml, publish_files, read_toml
from gainlink.shipping.artifact import Artifact, from_dict, render

from ..paths import project_root
from .bridge import RunResult, run_scenario
from .report import has_sigma, plots, report_json, sigma_csv, sigma_plot, summary_text
from .scenario import parse_scenario
from .showcase_report import comparison_png, showcase_summary

SHOWCASE_KEYS = {
    "spec",
    "single_point",
    "controller",
    "plant",
    "sweep",
    "steps",
    "transport",
    "step_timeout",
    "description",
}
DESIGNS = ("single", "scheduled")
SETTLE_BAND = 0.05  # settling: within 5 % of the step's size for good
# ... and "for good" must be seen: inside the band over at least the last quarter of the time after the step. A
# limit cycle wider than the band that happens to be inside it at the run's last sample has not settled.
SETTLE_HOLD = 0.25


@dataclass(frozen=True)
class ShowcaseResult:
    """The runs (design -> run name -> result), the comparison table (design -> metrics) and the summary."""

    runs: dict[str, dict[str, RunResult]]
    table: dict[str, dict]
    summary: str


def default_showcase(name: str = "tank_showcase") -> dict:
    """A built-in showcase description (``scenarios/<name>.toml`` of the package)."""
    path = resources.files("gainlink.hil").joinpath(f"scenarios/{name}.toml")
    if not path.is_file():
        raise ScenarioError(f"no built-in showcase {name!r}{did_you_mean(name, ['tank_showcase'])} (tank_showcase)")
    return parse_toml(path.read_text("utf-8"), what=f"built-in showcase {name}", error=ScenarioError)


def single_point_spec(spec: dict, sigma: float) -> dict:
    """The unscheduled spec of a scheduled ``spec`` at its point ``sigma``: that point's plant and operating
    point, the same weights, ``clamp`` anti-windup (the velocity form is the scheduled law's)."""
    data = copy.deepcopy(spec)
    sched = data.pop("schedule")
    points = [float(v) for v in sched["points"]]
    if float(sigma) not in points:
        raise ScenarioError(f"showcase: single_point {sigma} is not one of the schedule's points {points}")
    pt = sched["plant"][points.index(float(sigma))]
    data["plant"].update({k: pt[k] for k in ("A", "B", "C", "D") if k in pt})
    data["operating_point"] = {k: pt[k] for k in ("u_op", "y_op", "x_op") if k in pt}
    data["limits"]["anti_windup"] = "clamp"
    data["name"] = f"{spec.get('name', 'plant')}_single"[:32]
    return data


def run_showcase(
    *, report_dir: Path, spec_path: Path | None = None, controller: str | None = None, showcase: dict | None = None
) -> ShowcaseResult:
    """Design both, run them, compare; publish ``report.json``, ``summary.txt``, ``comparison.png`` and one
    folder per design and run (the HIL report of each, both twins in the sweep's) into ``report_dir``.

    Parameters
    ----------
    report_dir : Path
        Output folder.
    spec_path : Path, optional
        The scheduled spec (default: the description's ``spec``, relative to the checkout).
    controller : {"firmware", "reference"}, optional
        Overrides the description's controller (``firmware``: the host C; ``reference``: the float64 law).
    showcase : dict, optional
        A description (default: :func:`default_showcase`).
    """
    desc = _checked(showcase)
    spec_path = Path(spec_path) if spec_path else (project_root() or Path.cwd()) / desc["spec"]
    spec = read_toml(spec_path, what="showcase: spec", error=ScenarioError)[0]
    if "schedule" not in spec:
        raise ScenarioError(f"showcase: {spec_path} has no [schedule]")
    specs = {"single": single_point_spec(spec, desc["single_point"]), "scheduled": spec}
    runs: dict[str, dict[str, RunResult]] = {}
    files: dict[str, bytes | str] = {}
    for design in DESIGNS:
        art = _design(specs[design], source=f"{spec_path} ({design})")
        runs[design] = _run_design(art, desc, controller=controller or desc.get("controller", "firmware"))
        files[f"{design}/gains.json"] = render(art.data)
        files.update(_design_files(runs[design], design=design))
    table = {design: showcase_row(runs[design], desc) for design in DESIGNS}
    doc = {"designs": table, "spec": str(spec_path), "single_point": desc["single_point"], "sweep": desc["sweep"],
           "steps": desc["steps"]}  # fmt: skip
    files["report.json"] = json.dumps(doc, sort_keys=True, indent=2, allow_nan=False) + "\n"
    summary = showcase_summary(doc, report_dir=report_dir)
    files["summary.txt"] = summary
    files["comparison.png"] = comparison_png(runs, desc)
    publish_files(report_dir, files)
    return ShowcaseResult(runs=runs, table=table, summary=summary)


def _checked(showcase: dict | None) -> dict:
    """A copy of the description (the built-in one when none is given), its keys checked."""
    desc = dict(showcase or default_showcase())
    unknown = sorted(set(desc) - SHOWCASE_KEYS)
    if unknown:
        raise ScenarioError(f"showcase: unknown key(s) {', '.join(unknown)}")
    missing = [k for k in ("spec", "single_point", "plant", "sweep", "steps") if k not in desc]
    if missing:
        raise ScenarioError(f"showcase: missing {', '.join(missing)}")
    return desc


def _design(spec: dict, *, source: str) -> Artifact:
    from gainlink.laws import design
    from gainlink.spec import parse_spec

    return from_dict(design(parse_spec(spec, source=source)).artifact)


def _run_design(art: Artifact, desc: dict, *, controller: str) -> dict[str, RunResult]:
    """The sweep (with both twins) and each step (without) of one design."""
    sw = desc["sweep"]
    sweep = {"kind": "sweep", **{k: sw[k] for k in ("low", "high", "rate", "start")}}
    sweep_run = _scenario(desc, "sweep", sw["duration"], sw["low"], sweep, controller, twins=True)
    out = {"sweep": run_scenario(sweep_run, artifact=art)}
    for name, st in desc["steps"].items():
        ref = {"kind": "step", "initial": st["from"], "value": st["to"], "at": st["at"]}
        step = _scenario(desc, f"step_{name}", st["duration"], st["from"], ref, controller, twins=False)
        out[f"step_{name}"] = run_scenario(step, artifact=art)
    return out


def _scenario(desc: dict, name: str, duration: float, h0: float, reference: dict, controller: str, *, twins: bool):
    """A SIL scenario from rest at the level ``h0`` (flow ``c sqrt(h0)``, the plant's trim) on the description's
    plant; the output tracked is the schedule's (the tank's level ``h``)."""
    c = float(desc["plant"].get("parameters", {}).get("c", 0.4))
    return parse_scenario(
        {
            "name": f"showcase_{name}",
            "artifact": "unused.json",
            "transport": dict(desc.get("transport", {})),
            "step_timeout": float(desc.get("step_timeout", 1.0)),
            "plant": desc["plant"],
            "duration": float(duration),
            "controller": controller,
            "twin": twins,
            "model_twin": twins,
            "initial_state": {"q": c * float(np.sqrt(h0)), "h": float(h0)},
            "reference": {"r_h": reference},
        }
    )


def _design_files(runs: dict[str, RunResult], *, design: str) -> dict[str, bytes | str]:
    """Each run's HIL report (report.json, summary.txt; the sweep's plots, twins included, and for the scheduled
    design its sigma.csv and sigma.png) under design/run/."""
    files: dict[str, bytes | str] = {}
    for name, res in runs.items():
        files[f"{design}/{name}/report.json"] = report_json(res)
        files[f"{design}/{name}/summary.txt"] = summary_text(res)
        if name != "sweep":
            continue
        for png, data in plots(res).items():
            files[f"{design}/{name}/{png}"] = data
        if has_sigma(res):
            files[f"{design}/{name}/sigma.csv"] = sigma_csv(res.trace)
            files[f"{design}/{name}/sigma.png"] = sigma_plot(res)
    return files


def showcase_row(runs: dict[str, RunResult], desc: dict) -> dict[str, Any]:
    """One design's line of the comparison: tracking over the sweep (IAE and max |e| from its start, max |e| over
    the hold at its end from 2 s after the return), damping of each step, both twins, and the start (max |e| of
    each run before its reference moves, while the law starts from rest at the plant's trim)."""
    sw, d = runs["sweep"], desc["sweep"]
    moving = sw.trace.t >= d["start"]
    e = sw.trace.r[moving, 0] - sw.trace.y[moving, 0]
    back = sw.trace.t >= d["start"] + 2.0 * abs(d["high"] - d["low"]) / d["rate"] + 2.0  # held, 2 s after the return
    tail = sw.trace.r[back, 0] - sw.trace.y[back, 0]
    twin, model = sw.metrics.get("twin", {}), sw.metrics.get("model_twin", {})
    row: dict[str, Any] = {
        "complete": all(r.complete for r in runs.values()),
        "sweep_max_abs_e": float(np.max(np.abs(e))),
        "sweep_hold_max_abs_e": float(np.max(np.abs(tail), initial=0.0)),
        "twin_worst_du_rel": twin.get("worst_du_rel"),
        "twin_worst_dy_rel": twin.get("worst_dy_rel"),
        "model_twin_worst": model.get("worst"),
        "model_twin_warning": model.get("warning"),
        "sigma_coverage": (sw.metrics.get("schedule") or {}).get("coverage"),
    }
    row["sweep_iae"] = float(np.sum(np.abs(e)) * float(np.median(np.diff(sw.trace.t))))
    starts = {"sweep": start_max_abs_e(sw, d["start"])}
    for name, st in desc["steps"].items():
        row[f"step_{name}"] = step_metrics(runs[f"step_{name}"], st)
        starts[f"step_{name}"] = row[f"step_{name}"]["start_max_abs_e"]
    row["start_max_abs_e"] = max(starts.values())
    row["start_worst_run"] = max(starts, key=lambda k: starts[k])
    return row


def start_max_abs_e(res: RunResult, until: float) -> float:
    """The largest ``|r - y|`` of the tracked level before ``until`` (the reference still at its start value)."""
    before = res.trace.t < until
    return float(np.max(np.abs(res.trace.r[before, 0] - res.trace.y[before, 0]), initial=0.0))


def step_metrics(res: RunResult, step: dict) -> dict[str, float | bool | None]:
    """Overshoot (% of the step, past its target), settling time (last exit from the 5 % band, from the step; None
    when the level is not inside the band over the last :data:`SETTLE_HOLD` of the time after the step: not
    settled), IAE of the level after a reference step ``from -> to`` at ``at``, and max ``|e|`` before the step."""
    t, y = res.trace.t, res.trace.y[:, 0]
    after = t >= step["at"]
    size = float(step["to"]) - float(step["from"])
    past = (y[after] - step["to"]) * np.sign(size)
    e = np.abs(step["to"] - y[after])
    out = np.nonzero(e > SETTLE_BAND * abs(size))[0]
    Ts = float(np.median(np.diff(t)))
    settled = bool(out.size == 0 or out[-1] + 1 <= (1.0 - SETTLE_HOLD) * e.size)
    return {
        "overshoot_pct": float(max(0.0, np.max(past)) / abs(size) * 100.0),
        "settling_time_s": (float((out[-1] + 1) * Ts) if out.size else 0.0) if settled else None,
        "settled": settled,
        "iae": float(np.sum(e) * Ts),
        "start_max_abs_e": start_max_abs_e(res, step["at"]),
    }
