"""The campaign report streamed from the store: the same report as every row held at once, in bounded memory.

Oracles: the records the test stored, judged one at a time by :func:`.criteria.evaluate` (the per-record verdict) and
reduced here whole in memory (numpy's exact quantiles, Python's sort for the failure table, the CSV read back with the
csv module), and tracemalloc for the merge's memory per run.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import json
import math
import tracemalloc

import numpy as np
from gainlink.hil.campaign import parse_campaign
from gainlink.hil.campaign.block_file import encode_block, with_inputs
from gainlink.hil.campaign.plan import CampaignPlan, RunPoint, plan_campaign
from gainlink.hil.campaign.report import merge
from gainlink.hil.campaign.store import Store
from gainlink.shipping.artifact import canonical_json
from gainlink.version import __version__
from support.paths import EXAMPLES

GRID = [0.8, 1.0, 1.2]


def _campaign(runs: int, *, apply: str = "scale"):
    return parse_campaign(
        {
            "name": "streamed",
            "kind": "sil",
            "seed": 3,
            "runs": runs,
            "spec": str(EXAMPLES / "pendulum.toml"),
            "scenario": {"duration": 0.5, "plant": {"kind": "cart_pendulum"}},
            "grid": [{"target": "plant.parameters.m", "values": GRID, "apply": apply}],
            "draw": [{"target": "plant.parameters.M", "distribution": "uniform", "low": 0.7, "high": 1.3}],
            "criteria": {"stable": True, "settled_within": 2.0, "iae_below": 0.9},
        }
    )


def _record(rng: np.random.Generator, k: int) -> dict:
    """A finished run's record as a worker stores it (no trace), or an error every 17th run."""
    if k % 17 == 5:
        return {"status": "error", "reason": f"boom {k}"}
    iae = float(rng.lognormal(-0.5, 0.6))
    settle = None if k % 11 == 0 else float(rng.uniform(0.5, 3.0))
    return {
        "status": "done",
        "complete": True,
        "reason": None,
        "metrics": {
            "tracked": {"r_x": {"iae": iae, "overshoot_pct": float(rng.uniform(0, 30)), "settling_time_s": settle}},
            "outputs_final": {"x": float(rng.normal()), "theta": float(rng.normal())},
        },
        "measures": {
            "stable": k % 13 != 0,
            "unstable_reason": "growing" if k % 13 == 0 else None,
            "longest_saturation_s": 0.0,
            "output_min": {},
            "output_max": {},
            "model_mismatch": float(rng.uniform(0, 0.2)),
            "model_warning": k % 7 == 0,
        },
    }


def _stored_campaign(tmp_path, draws: int, records: dict | None = None) -> tuple[CampaignPlan, Store]:
    """A plan of ``len(GRID) * draws`` runs and a store holding a record of each, in blocks of 64 stored in reverse
    plan order (so the report cannot rely on the blocks' order); ``records``: filled with each block file's records
    by run id."""
    campaign = _campaign(draws)
    rng = np.random.default_rng(1)
    points = []
    for g, m in enumerate(GRID):
        for j in range(draws):
            k = len(points)
            seed, M = 1000 + j, float(rng.uniform(0.7, 1.3))
            points.append(
                RunPoint(
                    index=k,
                    id=f"{k:020x}",
                    grid_index=g,
                    draw=j,
                    values={"plant.parameters.m": m, "plant.parameters.M": M},
                    artifact_sha256="a" * 64,
                    scenario={"duration": 0.5, "plant": {"kind": "cart_pendulum", "parameters": {"M": M}}},
                    seed=seed,
                )
            )
    plan = CampaignPlan(campaign=campaign, runs=tuple(points))
    store = Store(tmp_path / "c", campaign="streamed")
    kept = points
    for start in reversed(range(0, len(kept), 64)):
        block = kept[start : start + 64]
        made = [with_inputs(_record(rng, p.index), p, kind="sil") for p in block]
        store.put_block(encode_block([p.id for p in block], made, campaign="streamed"))
        if records is not None:
            records[store.where(block[0].id).name] = {p.id: r for p, r in zip(block, made)}
    return plan, store


def _iae(row: dict) -> float | None:
    tr = row.get("metrics", {}).get("tracked", {})
    return None if not tr else sum(v["iae"] for v in tr.values())


def _row_by_hand(point: RunPoint, record: dict | None, criteria) -> dict:
    """Run ``point``'s row from the record the test stored (``None``: none), its verdict by :func:`evaluate`."""
    from gainlink.hil.campaign.criteria import evaluate

    head = {"index": point.index, "id": point.id, "grid_index": point.grid_index, "draw": point.draw,
            "values": point.values, "seed": point.seed, "artifact_sha256": point.artifact_sha256}  # fmt: skip
    if record is None:
        return head | {"status": "missing", "failed": ["missing"], "reasons": ["no result"]}
    if record["status"] == "error":
        return head | {"status": "error", "failed": ["error"], "reasons": [record["reason"]], "worker": None}
    failed = evaluate(criteria, record)
    row = {k: record[k] for k in ("complete", "metrics", "measures")} | {"run_reason": record["reason"]}
    verdict = {"status": "fail" if failed else "pass", "failed": sorted({k for k, _ in failed}),
               "reasons": [text for _, text in failed], "worker": None}  # fmt: skip
    return head | verdict | row


def test_the_streamed_report_is_the_report_of_every_row_at_once(tmp_path):
    stored: dict[str, dict] = {}
    plan, store = _stored_campaign(tmp_path, 100, stored)
    gone = sorted(p.name for p in store.files())[0]
    (store.out / "blocks" / gone).unlink()  # some runs missing
    held = {run_id: r for name, records in stored.items() if name != gone for run_id, r in records.items()}
    store = Store(store.out)  # a fresh index, as `campaign show` reads the folder
    summary, rows, counts = merge(plan, store, plots=True)
    doc = json.loads((store.out / "campaign.json").read_text())
    runs = [_row_by_hand(p, held.get(p.id), plan.campaign.criteria) for p in plan.runs]
    assert "runs" not in doc and len(rows) == 300  # campaign.json: counts, points, failures; a run's row: the store's
    assert list(rows) == runs and rows[-1] == runs[-1] and rows[5] == runs[5] and rows[-3:] == runs[-3:]
    assert {s: counts[s] for s in ("pass", "fail", "error", "missing")} == {
        s: sum(r["status"] == s for r in runs) for s in ("pass", "fail", "error", "missing")
    }
    assert doc["counts"] == {"runs": 300, **{s: counts[s] for s in ("pass", "fail", "error", "missing")}}
    assert 0 < counts["missing"] < 300 and counts["error"] and counts["fail"] and counts["pass"]
    for p in doc["points"]:
        mine = [r for r in runs if r["grid_index"] == p["grid_index"]]
        iae = [_iae(r) for r in mine if r["status"] in ("pass", "fail")]
        assert p["runs"] == len(mine) and p["pass"] == sum(r["status"] == "pass" for r in mine)
        assert p["iae_median"] == float(np.median(iae)) and p["iae_p95"] == float(np.percentile(iae, 95))
    with (store.out / "campaign.csv").open(newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [(int(t["index"]), t["id"], t["status"]) for t in table] == [
        (r["index"], r["id"], r["status"]) for r in runs
    ]
    assert all(
        float(t["r_x_iae"]) == r["metrics"]["tracked"]["r_x"]["iae"] for t, r in zip(table, runs) if "metrics" in r
    )
    bad = [r for r in runs if r["status"] != "pass"]
    bad.sort(key=lambda r: (r["status"] != "fail", -(_iae(r) or math.inf) if r["status"] == "fail" else 0))
    lines = (store.out / "failures.txt").read_text().splitlines()
    assert [ln.split()[1] for ln in lines[1:201]] == [r["id"] for r in bad[:200]]
    assert doc["failures"] == [{k: r[k] for k in ("index", "id", "status", "values", "reasons")} for r in bad[:200]]
    assert lines[-1] == f"... and {len(bad) - 200} more (campaign.csv has them all)"
    worst = max((r for r in runs if r["status"] in ("pass", "fail")), key=_iae)
    assert f"worst IAE: run {worst['index']} {worst['id']} " in summary
    for png in ("envelopes.png", "scatter.png"):
        assert (store.out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [p.name for p in store.out.iterdir() if p.name.startswith(".")]  # no temporary file left


def _merge_peak(tmp_path, draws: int) -> int:
    plan, store = _stored_campaign(tmp_path / str(draws), draws)
    store = Store(store.out)
    tracemalloc.start()
    try:
        merge(plan, store, plots=False)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_merging_holds_a_few_hundred_bytes_a_run_not_the_rows(tmp_path):
    """Every row held at once (a dict of its values, metrics and measures) is over 2 kB a run in Python; the
    streamed merge keeps an offset, a status and a few floats a run (the store's index aside)."""
    small, large = _merge_peak(tmp_path, 100), _merge_peak(tmp_path, 1000)
    per_run = (large - small) / (3 * 900)
    assert per_run < 1000, f"{per_run:.0f} bytes a run"


def _by_hand(campaign, sha: str, k: int) -> tuple[str, int, dict]:
    """Run ``k``'s id, seed and values as the plan's docstring defines them: grid point ``k // runs`` and draw
    ``k % runs``, whose seed and values come from its chunk of 1,024 draws: ``default_rng([seed, draw // 1024])``,
    the chunk's seeds first, then its values of M."""
    g, j = divmod(k, campaign.runs)
    rng = np.random.default_rng([campaign.seed, j // 1024])
    seed = int(rng.integers(2**31 - 1, size=1024)[j % 1024])
    M = float(rng.uniform(0.7, 1.3, size=1024)[j % 1024])
    scenario = copy.deepcopy(campaign.scenario)
    scenario["plant"].setdefault("parameters", {})
    scenario["plant"]["parameters"].update({"m": GRID[g], "M": M})
    body = {"kind": "sil", "artifact": sha, "scenario": scenario, "seed": seed, "gainlink": __version__}
    rid = hashlib.sha256(canonical_json(body).encode("ascii")).hexdigest()[:20]
    return rid, seed, {"plant.parameters.m": GRID[g], "plant.parameters.M": M}


def test_the_generated_plan_gives_each_run_the_id_seed_and_values_its_definition_gives(tmp_path):
    campaign = _campaign(100, apply="set")
    plan = plan_campaign(campaign)
    (sha,) = plan.artifacts
    runs = list(plan.runs)
    assert len(plan.runs) == len(runs) == 300
    for k, p in enumerate(runs):
        assert (p.id, p.seed, p.values) == _by_hand(campaign, sha, k)
        assert (p.index, p.grid_index, p.draw) == (k, k // 100, k % 100)
    for k in (0, 99, 100, 257, -1):  # read alone, a run is the one the walk gives
        assert plan.runs[k] == runs[k]


def test_a_plan_holds_no_run(tmp_path):
    """Holding every run (its RunPoint and scenario) costs kilobytes a run; the plan keeps its designs only."""
    plan_campaign(_campaign(1, apply="set"))  # what planning imports (SciPy, matplotlib: ~40 MB) is not a run's
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        plan = plan_campaign(_campaign(1000, apply="set"))
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(plan.runs) == 3000 and held / 3000 < 200, f"{held / 3000:.0f} bytes a run"


def test_the_plans_columns_are_each_runs_head_values(tmp_path):
    """The report's per-run arrays from the plan (grid point, each axis's value as a number and whether it is one)
    against each run's head, made one at a time; a choice axis of an int and a float, and values that are not numbers
    (a bool, a string, a table) as the scatter plot leaves them out."""
    from gainlink.hil.campaign.plan import _numbers, plan_columns

    data = {
        "name": "columns", "kind": "sil", "seed": 3, "runs": 40, "spec": str(EXAMPLES / "pendulum.toml"),
        "scenario": {"duration": 0.5, "plant": {"kind": "cart_pendulum"}},
        "grid": [{"target": "plant.parameters.m", "values": GRID}],
        "draw": [{"target": "plant.parameters.M", "distribution": "uniform", "low": 0.7, "high": 1.3},
                 {"target": "noise.x", "distribution": "choice", "values": [1, 0.002]}],
    }  # fmt: skip
    plan = plan_campaign(parse_campaign(data))
    cols = plan_columns(plan)
    heads = list(plan.runs.heads())
    assert cols.grid.tolist() == [h.grid_index for h in heads]
    assert cols.grid_values == {g: {"plant.parameters.m": m} for g, m in enumerate(GRID)}
    for name in ("plant.parameters.m", "plant.parameters.M", "noise.x"):
        assert cols.numbers[name].tolist() == [float(h.values[name]) for h in heads] and cols.numeric[name].all()
    assert {type(h.values["noise.x"]) for h in heads} == {int, float}
    x, ok = _numbers([True, "clamp", {"a": 1}, 2, 0.5])
    assert ok.tolist() == [False, False, False, True, True] and np.array_equal(x, [np.nan] * 3 + [2.0, 0.5], True)


def test_a_csv_field_is_what_csv_writer_writes_of_it():
    """A reason or axis value as one field of campaign.csv, against csv.writer's own row (the oracle) for text that
    needs no quotes and text with commas, quotes, line ends, a carriage return, spaces and non-ASCII letters."""
    import io

    from gainlink.hil.campaign.judged import csv_field

    texts = ["", "plain", "a, b", 'say "hi"', "two\nlines", "cr\rhere", " lead", "Ω-axis; θ left [-0.7, 0.7]", '"', ","]
    for text in texts:
        out = io.StringIO()
        csv.writer(out, lineterminator="\n").writerow(["x", text, "y"])
        assert "x," + csv_field(text) + ",y\n" == out.getvalue(), text
