"""Does the MPC law pay (issue 32, point 6)? The shipped pendulum campaign under MPC against LQI + back-calculation,
and a campaign over the solver's rho and cap.

1. ``examples/campaigns/pendulum_mpc_mass_uncertainty.toml`` (MPC, examples/pendulum_mpc.toml: N = 20, cap 10) and the
   same campaign with ``spec = "../pendulum.toml"`` (the LQI law of the same weights, anti_windup = "backcalc": the
   counterpart in pendulum_mass_uncertainty.toml): the same seed, so the same drawn plants (cart and pendulum masses
   +-30 %, length +-10 %), each started 1 m off its reference, under the limits as designed (+-20 N) and a box 8
   times narrower (+-2.5 N). Per law and box: the fraction of plants that stays up (the campaign's criteria: stable,
   |theta| <= 0.7 rad, |x| <= 2 m), the median settling time of the cart's position (2 % band; runs that settle) and
   its median IAE, and for the MPC the solver's iterations (mean over the runs' steps, worst) and the share of steps
   the cap stopped. Beside them, per box, the plants one law keeps up and the other does not (paired on the draw).
   The baseline measured in the same run is the LQI law: ``ratio_*`` are MPC / LQI. A third column runs the MPC
   with a soft box on the pendulum's angle, |theta| <= 0.4 rad (``THETA_BOX``), a limit LQI cannot be given.
2. ``rho_cap``: the MPC campaign at +-20 N over rho (x 1/10, 1, 10 of the default 3 mean(diag R)) and the cap (3, 10,
   40 iterations), :data:`RHO_CAP_DRAWS` plants each: how many iterations each plant needs, and what a tighter cap
   or another rho does to staying up and to the IAE.

Runs go through the campaign machinery's plan (preflight, the designs of the grid points) and its worker function
(``gainlink.hil.campaign.worker.execute``), one after the other in this process (no Dask: the figures, not the
throughput, are the point); the twins are off (the runs' own trajectories are what is compared).

    .venv/bin/python bench/mpc_pays.py > out/bench/mpc_pays.json       # ~10 min on one core
"""

from __future__ import annotations

import json
import logging
import statistics
import sys
import tomllib
from pathlib import Path

from gainlink.hil.campaign.config import parse_campaign
from gainlink.hil.campaign.criteria import evaluate
from gainlink.hil.campaign.plan import plan_campaign
from gainlink.hil.campaign.worker import execute

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = ROOT / "examples" / "campaigns" / "pendulum_mpc_mass_uncertainty.toml"
LAWS = {"mpc": "../pendulum_mpc.toml", "lqi_backcalc": "../pendulum.toml"}
#: The MPC with a soft box on the pendulum's angle (what LQI cannot be told): |theta| <= 0.4 rad.
THETA_BOX = {"name": "theta_box", "target": "spec.mpc.boxes.theta", "values": [[-0.4, 0.4]]}
RHO_CAP_DRAWS = 20
RHO = (0.3, 3.0, 30.0)
CAPS = (3, 10, 40)


def run_campaign(data: dict) -> list[dict]:
    """Every run of the campaign ``data`` (a campaign file's table), one row each."""
    plan = plan_campaign(parse_campaign(data, path=CAMPAIGN))
    rows = []
    for p in plan.runs:
        rec = execute("sil", plan.artifacts[p.artifact_sha256], p.scenario, p.seed, plan.blobs)
        failed = evaluate(plan.campaign.criteria, rec) if rec["status"] == "done" else [("run", rec.get("reason"))]
        tracked = rec.get("metrics", {}).get("tracked", {}).get("r_x", {})
        rows.append({"values": p.values, "draw": p.draw, "up": not failed, "failed": sorted({c for c, _ in failed}),
                     "settling_s": tracked.get("settling_time_s"),
                     "iae": tracked.get("iae"), "saturated_steps": rec.get("metrics", {}).get("saturated_steps"),
                     "mpc": rec.get("metrics", {}).get("mpc")})  # fmt: skip
    return rows


def campaign_data(*, spec: str, runs: int | None = None, grid: list | None = None) -> dict:
    data = tomllib.loads(CAMPAIGN.read_text())
    data["spec"] = spec
    data["scenario"]["twin"] = False
    if runs is not None:
        data["runs"] = runs
    if grid is not None:
        data["grid"] = grid
    return data


def summarise(rows: list[dict]) -> dict:
    """Fraction up, median settling time (of the runs that settle) and median IAE; the solver's iterations."""
    settled = [r["settling_s"] for r in rows if r["up"] and r["settling_s"] is not None]
    iae = [r["iae"] for r in rows if r["up"] and r["iae"] is not None]
    out = {"runs": len(rows), "stays_up": sum(r["up"] for r in rows) / len(rows),
           "settled_runs": len(settled), "settling_s_median": statistics.median(settled) if settled else None,
           "iae_median_of_runs_up": statistics.median(iae) if iae else None}  # fmt: skip
    for r in rows:  # which criteria the runs that fell failed (a run may fail several)
        for c in r["failed"]:
            out.setdefault("failed_criteria", {}).setdefault(c, 0)
            out["failed_criteria"][c] += 1
    mpc = [r["mpc"] for r in rows if r["mpc"] and r["mpc"]["solved_steps"]]
    if mpc:
        steps = sum(b["solved_steps"] for b in mpc)
        out["iterations_mean"] = sum(b["iterations_mean"] * b["solved_steps"] for b in mpc) / steps
        out["iterations_worst"] = max(b["iterations_max"] for b in mpc)
        out["capped_fraction_of_steps"] = sum(b["capped_steps"] for b in mpc) / steps
        out["runs_needing_the_cap"] = sum(b["capped_steps"] > 0 for b in mpc)
    return out


def compare(runs: int | None) -> dict:
    """Part 1 (module docstring)."""
    rows = {law: run_campaign(campaign_data(spec=spec, runs=runs)) for law, spec in LAWS.items()}
    grid = tomllib.loads(CAMPAIGN.read_text())["grid"] + [THETA_BOX]
    rows["mpc_theta_box"] = run_campaign(campaign_data(spec=LAWS["mpc"], runs=runs, grid=grid))
    out = {}
    for box in (1.0, 0.125):
        by = {law: [r for r in rs if r["values"]["box"] == box] for law, rs in rows.items()}
        s = {law: summarise(rs) for law, rs in by.items()}
        entry = {"box_N": 20.0 * box, **s}
        for mpc in ("mpc", "mpc_theta_box"):
            pairs = list(zip(by[mpc], by["lqi_backcalc"], strict=True))
            assert all(a["values"]["M_factor"] == b["values"]["M_factor"] for a, b in pairs), "other plants drawn"
            entry[f"{mpc}_up_lqi_down"] = sum(a["up"] and not b["up"] for a, b in pairs)
            entry[f"lqi_up_{mpc}_down"] = sum(b["up"] and not a["up"] for a, b in pairs)
            for key in ("stays_up", "settling_s_median", "iae_median_of_runs_up"):
                base, new = s["lqi_backcalc"][key], s[mpc][key]
                entry[f"ratio_{mpc}_{key}"] = None if not base or new is None else round(new / base, 3)
        out[f"box_{20.0 * box:g}N"] = entry
    return out


def rho_cap() -> list[dict]:
    """Part 2 (module docstring)."""
    grid = [{"name": "rho", "target": "spec.mpc.rho", "values": list(RHO)},
            {"name": "cap", "target": "spec.mpc.max_iter", "values": list(CAPS)}]  # fmt: skip
    rows = run_campaign(campaign_data(spec=LAWS["mpc"], runs=RHO_CAP_DRAWS, grid=grid))
    out = []
    for rho in RHO:
        for cap in CAPS:
            sel = [r for r in rows if r["values"]["rho"] == rho and r["values"]["cap"] == cap]
            out.append({"rho": rho, "cap": cap, **summarise(sel)})
    return out


def main() -> None:
    logging.basicConfig(level=logging.WARNING)
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else None
    out = {"benchmark": "mpc_pays", "campaign": str(CAMPAIGN.relative_to(ROOT)), "baseline": "lqi_backcalc",
           "compare": compare(runs), "rho_cap": rho_cap()}  # fmt: skip
    json.dump(out, sys.stdout, indent=2)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
