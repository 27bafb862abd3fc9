"""A block file's verdict inputs as typed columns, and the verdicts and CSV cells made from them at once.

Oracles: the per-row :func:`gainlink.hil.campaign.criteria.evaluate` on each run's stored JSON row (decoded with the
json module), the CSV cells as ``csv.writer`` writes each decoded value (floats by ``repr``, ``None`` empty), and the
records handed to the store.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from collections import Counter

import numpy as np
import pyarrow.parquet as pq
import pytest
from gainlink.hil.campaign import parse_campaign
from gainlink.hil.campaign.block_file import encode_block, with_inputs
from gainlink.hil.campaign.block_layout import MEASURE_CELLS, METRIC_CELLS, METRIC_COLUMNS, RECORD_COLUMNS, ROW_KEYS
from gainlink.hil.campaign.block_texts import metric_texts, record_texts
from gainlink.hil.campaign.config import Criteria
from gainlink.hil.campaign.criteria import evaluate, evaluate_columns
from gainlink.hil.campaign.plan import CampaignPlan, RunPoint
from gainlink.hil.campaign.report import merge
from gainlink.hil.campaign.store import Store
from support.paths import EXAMPLES

CRITERIA = Criteria(
    stable=True,
    bounds={"theta": (-0.7, 0.7), "x": (-2.0, 2.0)},
    settled_within=2.0,
    overshoot_below=20.0,
    saturated_at_most=0.5,
    iae_below=0.9,
    twin_deviation_below=0.01,
)


def _maybe(rng: np.random.Generator, value: float, p: float = 0.02) -> float | None:
    return None if rng.random() < p else value


def _record(rng: np.random.Generator, k: int) -> dict:
    """A run's record of every kind a store holds: errors (with and without a worker), incomplete and unstable
    runs, measures and metrics that are ``None`` (not finite), a tracked output or an output a run lacks, a run
    without a twin, and plain passes."""
    if k % 23 == 7:
        return {"status": "error", "reason": f"boom {k}"} | ({"worker": {"host": "h", "pid": k}} if k % 2 else {})
    complete = k % 19 != 3
    tracked = {
        name: {"iae": _maybe(rng, float(rng.lognormal(-1.5, 0.5))),
               "overshoot_pct": _maybe(rng, float(rng.uniform(0, 22)), 0.2),
               "settling_time_s": _maybe(rng, float(rng.uniform(0.5, 2.2))), "start_s": 0.0}
        for name in (("r_x", "r_theta") if k % 5 else ("r_x",)) if not (k % 31 == 4)
    }  # fmt: skip
    outs = ("theta", "x") if k % 29 != 6 else ("x",)
    measures = {
        "stable": complete and k % 13 != 0,
        "unstable_reason": None if complete and k % 13 else ("run stopped" if not complete else "grows"),
        "longest_saturation_s": float(rng.choice([0.0, 0.0, 0.0, 0.3, 0.7])),
        "output_min": {o: _maybe(rng, float(rng.uniform(-0.75, 0.0))) for o in outs},
        "output_max": {o: _maybe(rng, float(rng.uniform(0.0, 0.75))) for o in outs},
        "model_mismatch": _maybe(rng, float(rng.uniform(0, 0.2)), 0.3),
        "model_warning": bool(k % 7 == 0),
        "growth_ratio": {} if not complete or k % 13 == 0 else {"r_x": _maybe(rng, 0.5, 0.2)},
    }
    if k % 41 == 5 and measures["growth_ratio"]:  # an int where the measures' floats are: JSON's "1", not "1.0"
        measures["growth_ratio"] = {"r_x": 1}
    if k % 17:
        measures |= {"twin_output_deviation": _maybe(rng, float(rng.uniform(0, 0.011))),
                     "twin_command_deviation": float(rng.uniform(0, 0.02)), "model_iae_ratio": 1.25}  # fmt: skip
    if k % 11 == 2:  # a run without a model twin: none of its keys
        measures = {key: v for key, v in measures.items() if not key.startswith("model_")}
    metrics = {"tracked": tracked, "outputs_final": {o: _maybe(rng, float(rng.normal())) for o in outs}, "steps": 10}
    worker = {"host": "vm", "pid": 40 + k, "start": 1.5, "stop": 2.25, "cpu_s": 0.125} | ({"block": 9} if k % 3 else {})
    return {"status": "done", "complete": complete, "reason": None if complete else "run stopped",
            "metrics": metrics, "measures": measures, "worker": worker}  # fmt: skip


def _stored(tmp_path, runs: int = 300) -> tuple[CampaignPlan, Store, dict[str, dict]]:
    campaign = parse_campaign(
        {"name": "columns", "kind": "sil", "seed": 3, "runs": runs, "spec": str(EXAMPLES / "pendulum.toml"),
         "scenario": {"duration": 0.5, "plant": {"kind": "cart_pendulum"}},
         "draw": [{"target": "plant.parameters.M", "distribution": "uniform", "low": 0.7, "high": 1.3}]}
    )  # fmt: skip
    rng = np.random.default_rng(5)
    points, records = [], {}
    for k in range(runs):
        point = RunPoint(index=k, id=f"{k:020x}", grid_index=0, draw=k, values={"plant.parameters.M": float(k)},
                         artifact_sha256="a" * 64, scenario={}, seed=k)  # fmt: skip
        points.append(point)
        records[points[-1].id] = with_inputs(_record(rng, k), points[-1], kind="sil")
    store = Store(tmp_path / "c", campaign="columns")
    for start in range(0, runs, 64):
        block = points[start : start + 64]
        store.put_block(encode_block([p.id for p in block], [records[p.id] for p in block], campaign="columns"))
    plan = CampaignPlan(campaign=dataclasses.replace(campaign, criteria=CRITERIA), runs=tuple(points))
    return plan, Store(store.out), records


def test_the_verdicts_over_columns_are_each_rows_own_evaluate(tmp_path):
    _, store, records = _stored(tmp_path)
    judged = 0
    for part in store.report_parts(rows=True):
        got = evaluate_columns(CRITERIA, part.judged)
        for i, run_id in enumerate(part.ids.tolist()):
            row = json.loads(part.rows[i])
            if records[run_id.decode()]["status"] == "error":
                assert part.error[i]
                continue
            assert got[i] == evaluate(CRITERIA, row), run_id
            judged += 1
    assert judged > 250
    kinds = [name for rec in records.values() if rec["status"] == "done" for name, _ in evaluate(CRITERIA, rec)]
    assert {"stable", "bounds", "settled_within", "overshoot_below", "iae_below", "saturated_at_most",
            "twin_deviation_below"} <= set(kinds)  # fmt: skip


def _cells(row: dict, reasons: list[str]) -> list[str]:
    """The CSV cells after the axes and seed, from the decoded row (the run's own tracked outputs and outputs)."""
    m, q = row.get("metrics", {}), row.get("measures", {})
    values = [row.get("complete"), *(q.get(k) for k in MEASURE_CELLS)]
    values += [m["tracked"][t].get(k) for t in sorted(m.get("tracked", {})) for k in METRIC_CELLS]
    values += [m["outputs_final"][o] for o in sorted(m.get("outputs_final", {}))]
    return ["; ".join(reasons), *(repr(x) if isinstance(x, float) else "" if x is None else str(x) for x in values)]


def test_the_report_rows_and_csv_cells_from_columns_are_each_rows_own(tmp_path):
    plan, store, records = _stored(tmp_path)
    _, rows, _ = merge(plan, store, plots=False)
    runs = list(rows)
    with (store.out / "campaign.csv").open(newline="") as fh:
        head, *table = list(csv.reader(fh))
    at = head.index("complete")
    for run, cells in zip(runs, table, strict=True):
        record = json.loads(json.dumps(records[run["id"]], sort_keys=True))  # as stored: the keys sorted
        record.pop("inputs")
        if record["status"] == "error":
            expected = {"status": "error", "failed": ["error"], "reasons": [record.pop("reason")]}
            expected |= {} if "worker" in record else {"worker": None}
        else:
            failed = evaluate(CRITERIA, record)
            expected = {"status": "fail" if failed else "pass", "failed": sorted({k for k, _ in failed}),
                        "reasons": [t for _, t in failed], "run_reason": record.pop("reason")}  # fmt: skip
        expected |= {k: v for k, v in record.items() if k != "status"}
        assert {k: v for k, v in run.items() if k in expected} == expected and run["status"] == cells[2]
        own = _cells(record, expected["reasons"])
        columns = dict(zip(head, cells))
        assert [columns["reasons"], *cells[at : at + 1 + len(MEASURE_CELLS)]] == own[: 2 + len(MEASURE_CELLS)]
        tail = [columns[f"{t}_{k}"] for t in sorted(record.get("metrics", {}).get("tracked", {})) for k in METRIC_CELLS]
        tail += [columns[f"{o}_final"] for o in sorted(record.get("metrics", {}).get("outputs_final", {}))]
        assert tail == own[2 + len(MEASURE_CELLS) :]
    assert min(Counter(r["status"] for r in runs).values()) > 10


def test_a_blocks_typed_columns_hold_its_rows_numbers_and_the_record_is_the_one_stored(tmp_path):
    _, store, records = _stored(tmp_path, runs=64)
    for run_id, record in records.items():
        assert store.record(run_id) == record | {"id": run_id}
    assert dict(store.records()) == {k: r | {"id": k} for k, r in records.items()}
    cpu = [r["worker"].get("cpu_s", 0.0) for r in records.values() if r.get("worker")]
    assert len(cpu) > 10 and store.runs_cpu_s() == pytest.approx(sum(cpu), rel=1e-12)  # what the bench counts
    (path,) = store.files()
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    for i, run_id in enumerate(table.column("id").to_pylist()):
        rec = records[run_id]
        done = rec["status"] == "done"
        measures = table.column("measures")[i].as_py()
        assert measures == (
            {k: rec["measures"].get(k) for k in ("stable", "unstable_reason", *MEASURE_CELLS[1:], "model_warning")}
            if done
            else None
        )
        tracked = table.column("tracked")[i].as_py()
        mine = rec.get("metrics", {}).get("tracked", {})
        assert {k: v for k, v in (tracked or {}).items() if v is not None} == {
            t: {k: v[k] for k in METRIC_CELLS} for t, v in mine.items()
        }
        assert table.column("worker")[i].as_py() == (
            None
            if "worker" not in rec
            else {k: rec["worker"].get(k) for k in ("host", "pid", "start", "stop", "cpu_s", "block")}
        )
        assert table.column("complete")[i].as_py() == rec.get("complete")
        assert table.column("run_reason")[i].as_py() == (rec.get("reason") if done else None)
        names = json.loads(table.column("names")[i].as_py())
        assert names == [sorted(mine), sorted(rec.get("metrics", {}).get("outputs_final", {}))]


@pytest.mark.parametrize("layout", ["2", "3", "4", "5", "6", "7", None])
def test_a_block_of_an_earlier_layout_is_refused_on_resume_in_one_line(tmp_path, layout):
    import pyarrow as pa
    import pyarrow.parquet as pq
    from gainlink.hil.campaign.config import CampaignError
    from gainlink.hil.campaign.store import refuse_foreign
    from gainlink.version import __version__

    out = tmp_path / "out"
    (out / "blocks").mkdir(parents=True)
    (out / "plan.json").write_text(json.dumps({"campaign": {"name": "mine", "gainlink": __version__}, "runs": []}))
    table = pq.read_table(pa.BufferReader(encode_block(["x"], [{"status": "error", "reason": "r"}], campaign="mine")))
    meta = {b"gainlink.campaign": b"mine", b"gainlink.version": __version__.encode()}
    meta |= {} if layout is None else {b"gainlink.block_layout": layout.encode()}
    pq.write_table(table.replace_schema_metadata(meta), out / "blocks" / "0123456789abcdef01234567.parquet")
    with pytest.raises(CampaignError, match=r"is a block file of an earlier layout \(before 8\)") as err:
        refuse_foreign(out, {"campaign": {"name": "mine"}})
    assert "\n" not in str(err.value)


def _row_text(record: dict) -> str:
    """A stored record's report row as text, as json writes it (keys sorted, compact): what the block stored as JSON
    before layout 5 and ``campaign.json`` gives as it is."""
    row = {k: record[k] for k in ("complete", "measures", "metrics", "worker") if k in record}
    if record["status"] != "error" and "reason" in record:
        row["run_reason"] = record["reason"]
    return json.dumps(row, sort_keys=True, separators=(",", ":"), allow_nan=False)


def test_a_rows_text_made_from_the_typed_columns_is_the_json_of_its_row(tmp_path):
    """Every kind of record (errors with and without a worker, runs without a twin, an output or a growth ratio,
    None measures, an int among the floats) gives its row's text exactly; a row whose typed columns give it keeps no
    JSON of it but its metrics', the others keep the whole row."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from gainlink.hil.campaign.block_texts import metric_texts, row_texts

    _, store, records = _stored(tmp_path)
    checked, given = 0, 0
    for part in store.report_parts(rows=True):
        for i, run_id in enumerate(part.ids.tolist()):
            assert part.rows[i] == _row_text(records[run_id.decode()]), run_id
            checked += 1
    for path in store.files():
        table = pq.read_table(path)
        assert row_texts(table) == [_row_text(records[i]) for i in table.column("id").to_pylist()]
        whole = table.column("row").is_null().to_pylist()
        given += sum(whole)
        texts = metric_texts(table)
        for i, (run_id, stored) in enumerate(zip(table.column("id").to_pylist(), texts)):
            metrics = records[run_id].get("metrics")
            assert stored == (None if not whole[i] or metrics is None else json.dumps(
                metrics, sort_keys=True, separators=(",", ":"), allow_nan=False))  # fmt: skip
        # a file of layout 6 (the metrics' texts in ``metrics``, no form) reads the same
        earlier = table.drop_columns(["metrics_form", "metrics_slots", "metrics_numbers"])
        earlier = earlier.set_column(earlier.column_names.index("metrics"), "metrics", pa.array(texts, pa.string()))
        assert metric_texts(earlier) == texts and row_texts(earlier) == row_texts(table)
    assert checked == len(records) and 200 < given < checked  # most rows from their columns, the odd ones whole


def test_a_shipped_runs_row_is_made_from_its_columns(tmp_path):
    """The records a worker makes of the shipped pendulum's runs: no row stored as JSON, only its metrics; the text
    made from the columns is json's of the record's row, and the record read back is the one made."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from gainlink.fileio import read_toml
    from gainlink.hil.campaign.block_file import encode_block
    from gainlink.hil.campaign.block_texts import row_texts
    from gainlink.hil.campaign.plan import plan_campaign
    from gainlink.hil.campaign.worker import batch_records

    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    data.update(runs=8, seed=2026, spec=str((path.parent / data["spec"]).resolve()))
    campaign = parse_campaign(data)
    plan = plan_campaign(campaign)
    runs = [(p.artifact_sha256, p.scenario, p.seed) for p in plan.runs]
    records = batch_records("sil", dict(plan.artifacts), runs)
    records = [with_inputs(r, run, kind="sil") for r, run in zip(records, runs)]
    ids = [p.id for p in plan.runs]
    table = pq.read_table(pa.BufferReader(encode_block(ids, records, campaign=campaign.name)))
    assert table.column("row").null_count == len(ids)
    expected = [_row_text(r) for r in records]
    assert row_texts(table) == expected
    assert {json.loads(t)["measures"]["stable"] for t in expected} == {True, False}  # a failed run among them
    store = Store(tmp_path / "s", campaign=campaign.name)
    store.put_block(encode_block(ids, records, campaign=campaign.name))
    for run_id, record in zip(ids, records):
        assert store.record(run_id) == json.loads(json.dumps({k: v for k, v in record.items() if k != "trace"})) | {
            "id": run_id
        }


def _verdict(record: dict | None) -> dict:
    """A run's verdict head as the report defines it, from its record (``None``: no record)."""
    if record is None:
        return {"status": "missing", "failed": ["missing"], "reasons": ["no result"]}
    if record["status"] == "error":
        return {"status": "error", "failed": ["error"], "reasons": [record["reason"]]} | (
            {} if "worker" in record else {"worker": None}
        )
    failed = evaluate(CRITERIA, json.loads(json.dumps(record, sort_keys=True)))  # as stored: the keys sorted
    head = {"status": "fail" if failed else "pass", "failed": sorted({k for k, _ in failed}),
            "reasons": [t for _, t in failed]}  # fmt: skip
    return head | {k: None for k, r in (("complete", "complete"), ("run_reason", "reason"), ("worker", "worker"))
                   if r not in record}  # fmt: skip


def _axis_cell(value) -> str:
    return repr(value) if type(value) is float else value if isinstance(value, str) else json.dumps(value)


def _report_by_rows(plan, records: dict[str, dict], stored: set[str]) -> tuple[str, list[dict]]:
    """``campaign.csv`` and the runs' rows as the report made them a row at a time before its rows were made a chunk
    at a time: each head a dict of the run's point, each verdict and row by json, each CSV row by ``csv.writer``, from
    the records themselves (runs not ``stored``: missing)."""
    import io

    from gainlink.hil.campaign.plan import run_heads
    from gainlink.hil.campaign.report import csv_head

    mine = [records[i] for i in stored if records[i]["status"] != "error"]
    tracked = {t for r in mine for t in r["metrics"]["tracked"]}
    outs = {o for r in mine for o in r["metrics"]["outputs_final"]}
    axes = [a.name for a in (*plan.campaign.grid, *plan.campaign.draws)]
    out, lines = io.StringIO(), []
    w = csv.writer(out, lineterminator="\n")
    w.writerow(csv_head(plan, tracked, outs))
    for head in run_heads(plan):
        record = records[head.id] if head.id in stored else None
        verdict = _verdict(record)
        verdict_text = json.dumps(verdict, sort_keys=True)
        row = _row_text(record) if record is not None else "{}"
        body = verdict_text if row == "{}" else verdict_text[:-1] + ", " + row[1:]
        point = {"index": head.index, "id": head.id, "grid_index": head.grid_index, "draw": head.draw,
                 "values": head.values, "seed": head.seed, "artifact_sha256": head.artifact_sha256}  # fmt: skip
        lines.append(point | json.loads(body))
        rec = record if record is not None and record["status"] != "error" else {}
        m, q = rec.get("metrics", {}), rec.get("measures", {})
        cells = [rec.get("complete"), *(q.get(k) for k in MEASURE_CELLS)]
        cells += [m.get("tracked", {}).get(t, {}).get(k) for t in sorted(tracked) for k in METRIC_CELLS]
        cells += [m.get("outputs_final", {}).get(o) for o in sorted(outs)]
        values = [_axis_cell(head.values[a]) for a in axes]
        w.writerow([head.index, head.id, verdict["status"], "; ".join(verdict["reasons"]), *values, head.seed, *cells,
                    head.artifact_sha256 or ""])  # fmt: skip
    return out.getvalue(), lines


@pytest.mark.parametrize("generated", [True, False])
def test_the_rows_made_a_chunk_at_a_time_are_the_rows_made_one_by_one(tmp_path, generated, monkeypatch):
    """campaign.csv byte for byte and the rows (``CampaignResult.rows``) against the same rows made one at a time by the
    per-row functions (a generated plan of a grid and two drawn axes, an int and a float among a choice's values,
    more runs than a chunk; and a plan of points, one of them planned twice), on a store with errors, None measures
    and metrics, failed runs, runs of other tracked outputs and outputs than the others, runs with and without a model
    twin, and runs with no record."""
    import gainlink.hil.campaign.rows as csv_rows
    from gainlink.hil.campaign.plan import plan_campaign

    monkeypatch.setattr(csv_rows, "HEAD_CHUNK", 128)  # chunks of fewer runs than the plan's, one of them part-filled
    if generated:
        campaign = parse_campaign(
            {"name": "columns", "kind": "sil", "seed": 3, "runs": 130, "spec": str(EXAMPLES / "pendulum.toml"),
             "scenario": {"duration": 0.5, "plant": {"kind": "cart_pendulum"}},
             "grid": [{"target": "plant.parameters.m", "values": [0.1, 0.2, 0.3]}],
             "draw": [{"target": "plant.parameters.M", "distribution": "uniform", "low": 0.7, "high": 1.3},
                      {"target": "noise.x", "distribution": "choice", "values": [1, 0.002]}],
             "criteria": dataclasses.asdict(CRITERIA) | {"bounds": {k: list(v) for k, v in CRITERIA.bounds.items()}}}
        )  # fmt: skip
        plan = plan_campaign(campaign)
        assert len(plan.runs) > csv_rows.HEAD_CHUNK and len(plan.runs) % csv_rows.HEAD_CHUNK
        rng = np.random.default_rng(8)
        records = {h.id: with_inputs(_record(rng, h.index), (h.artifact_sha256, {}, h.seed), kind="sil")
                   for h in plan.runs.heads()}  # fmt: skip
        store = Store(tmp_path / "g", campaign="columns")
        ids = list(records)
        for start in range(0, len(ids), 50):
            store.put_block(encode_block(ids[start : start + 50], [records[i] for i in ids[start : start + 50]],
                                         campaign="columns"))  # fmt: skip
    else:
        plan, store, records = _stored(tmp_path)
    stored = {i.decode() for i in store._table()[0].tolist()}
    dropped = sorted(store.files())[1]
    stored -= set(pq.read_table(dropped, columns=["id"]).column("id").to_pylist())
    if not generated:  # a stored run planned twice, in the middle of the plan: its row each time
        twice = next(p for p in plan.runs if p.id in stored and records[p.id]["status"] == "done" and p.index > 100)
        runs = list(plan.runs)
        runs.insert(150, twice)
        plan = dataclasses.replace(plan, runs=tuple(dataclasses.replace(p, index=k) for k, p in enumerate(runs)))
    dropped.unlink()
    store = Store(store.out)
    _, rows, _ = merge(plan, store, plots=False)
    csv_text, by_rows = _report_by_rows(plan, records, stored)
    assert (store.out / "campaign.csv").read_text() == csv_text
    assert list(rows) == by_rows
    assert {"missing", "error", "fail", "pass"} <= {row["status"] for row in by_rows}


def test_a_run_planned_twice_is_one_of_the_envelopes_runs(tmp_path):
    """A stored run planned twice (a plan of points): the runs the envelopes choose from (the tally's status) are the
    finished runs once each, in plan order where each is first, each with its own draw (the points', by hand)."""
    from gainlink.hil.campaign.report import tallied
    from gainlink.hil.campaign.rows import Verdicts, plan_ids

    plan, store, records = _stored(tmp_path)
    runs = list(plan.runs)
    runs.insert(150, runs[120])
    plan = dataclasses.replace(plan, runs=tuple(dataclasses.replace(p, index=k) for k, p in enumerate(runs)))
    verdicts = Verdicts(plan.campaign.criteria, plan_ids(plan)).complete(store)
    try:
        status = tallied(plan, verdicts).status
    finally:
        verdicts.close()
    first: dict[str, RunPoint] = {}
    for p in runs:
        first.setdefault(p.id, p)
    finished = [p for p in first.values() if records[p.id]["status"] == "done"]
    assert len(finished) < len(runs) - 1 and records[runs[120].id]["status"] == "done"
    assert list(status) == [p.id for p in finished]
    assert status.draws.tolist() == [p.draw for p in finished]


@pytest.mark.parametrize("where", ["twin_output_deviation", "output_min", "worker"])
def test_a_row_with_a_value_json_refuses_is_refused_as_json_refuses_it(where):
    """A NaN or an infinity among the values a row's text would be made from: the block is refused as json refuses
    the row (ValueError), not written with a text json would never write."""
    record = _record(np.random.default_rng(0), 1)
    if where == "worker":
        record["worker"]["start"] = float("nan")
    elif where == "output_min":
        record["measures"]["output_min"]["x"] = float("-inf")
    else:
        record["measures"][where] = float("nan")
    with pytest.raises(ValueError):
        json.dumps(record, allow_nan=False)
    with pytest.raises(ValueError):
        encode_block(["x"], [record], campaign="c")


def _table(data: bytes):
    import pyarrow as pa

    return pq.read_table(pa.BufferReader(data))


def test_a_blocks_runs_as_lists_make_the_file_their_records_make():
    """A block's finished runs given as lists (``store.encode_runs``, no record dict a run) make the table their
    records make through ``encode_block`` (its oracle), column by column, schema and metadata: runs of every form a
    record takes (measures None, without the twins' keys, an int among the floats, a worker without ``block``, NaN
    where JSON says null), so the typed columns' checks fall back run by run."""
    from gainlink.hil.campaign.block_columns import BlockRuns
    from gainlink.hil.campaign.block_file import encode_runs

    rng = np.random.default_rng(11)
    records = [r for k in range(120) if (r := _record(rng, k))["status"] == "done"]
    links = [{"kind": "sil (in-process, no link)"} if k % 5 else {"kind": "x", "n": k} for k in range(len(records))]
    inputs = [("a" * 64, {"plant": {"M": 1.0 + k / 7}, "duration": 1.0}, k) for k in range(len(records))]
    ids = [f"{k:020x}" for k in range(len(records))]
    runs = BlockRuns(
        kind="sil",
        inputs=inputs,
        complete=[r["complete"] for r in records],
        reason=[r["reason"] for r in records],
        metrics=[r["metrics"] for r in records],
        measures=[r["measures"] for r in records],
        link=links,
        traces=[None] * len(records),
        worker=[r["worker"] for r in records],
    )
    made = _table(encode_runs(ids, runs, campaign="c"))
    full = [with_inputs(r | {"link": link}, point, kind="sil") for r, link, point in zip(records, links, inputs)]
    oracle = _table(encode_block(ids, full, campaign="c"))
    assert made.schema.equals(oracle.schema, check_metadata=True)
    for name in oracle.column_names:
        assert made.column(name).equals(oracle.column(name)), name
    assert 0 < made.column("row").null_count < len(ids)  # some rows from their columns, the odd ones whole


def test_a_blocks_run_its_typed_columns_cannot_give_is_stored_whole_with_its_metrics_from_the_trees():
    """One block's runs, their metrics only as its column trees (no dict a run), one run's measures of a form the
    typed columns cannot give (an int among the floats): the file is the one the records make through
    ``encode_block`` column by column, that run's row stored whole with the metrics its record holds."""
    from dataclasses import replace

    from gainlink.fileio import read_toml
    from gainlink.hil.campaign import worker
    from gainlink.hil.campaign.block_file import encode_runs
    from gainlink.hil.campaign.plan import plan_campaign

    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    data.update(runs=3, seed=7, spec=str((path.parent / data["spec"]).resolve()))
    plan = plan_campaign(parse_campaign(data))
    points = [p for p in plan.runs if p.grid_index == 0]
    runs, ids = [(p.artifact_sha256, p.scenario, p.seed) for p in points], [p.id for p in points]
    task = worker._task_records("sil", dict(plan.artifacts), runs, None)
    lists = worker._block_runs("sil", runs, task)
    assert lists.metrics is None and lists.metric_trees is not None
    records = [with_inputs(r, run, kind="sil") for r, run in zip(worker._materialized(task), runs)]
    odd = dict(lists.measures[1], longest_saturation_s=1)
    lists = replace(lists, measures=[m if k != 1 else odd for k, m in enumerate(lists.measures)])
    records[1] = records[1] | {"measures": odd}
    table, oracle = _table(encode_runs(ids, lists, campaign="c")), _table(encode_block(ids, records, campaign="c"))
    assert table.schema.equals(oracle.schema, check_metadata=True)
    for name in oracle.column_names:
        assert table.column(name).equals(oracle.column(name)), name
    rows = table.column("row").to_pylist()
    assert rows[0] is None and rows[2] is None and json.loads(rows[1])["metrics"] == records[1]["metrics"]


@pytest.mark.parametrize("interleaved", [True, False])
def test_a_workers_block_file_is_the_one_its_records_make(tmp_path, interleaved):
    """The shipped pendulum's runs in a worker's task, two grid points' blocks interleaved (or one grid point's block,
    whose traces go to the file as the block's arrays, not a run's at a time): the block file made from the blocks'
    lists (``worker._block_runs``, ``store.encode_runs``: the worker's path) is the table the same runs' records make
    through ``encode_block`` (the per-run path's), column by column (the blocks' metrics, from each block's column
    trees, in a form a block where the records' dicts make one for the task: the same texts read back); ``campaign
    show``'s record of each run is its record."""
    from gainlink.fileio import read_toml
    from gainlink.hil.campaign import block_columns, worker
    from gainlink.hil.campaign.block_file import encode_runs
    from gainlink.hil.campaign.plan import plan_campaign

    path = EXAMPLES / "campaigns" / "pendulum_mass_uncertainty.toml"
    data, _ = read_toml(path, what="campaign", error=ValueError)
    data.update(runs=4, seed=2026, spec=str((path.parent / data["spec"]).resolve()))
    campaign = parse_campaign(data)
    plan = plan_campaign(campaign)
    points = sorted(plan.runs, key=lambda p: (p.draw, p.grid_index))  # grid points' runs interleaved in the task
    if not interleaved:
        points = [p for p in points if p.grid_index == 0]
    runs = [(p.artifact_sha256, p.scenario, p.seed) for p in points]
    ids = [p.id for p in points]
    task = worker._task_records("sil", dict(plan.artifacts), runs, None)
    assert all(type(r) is worker._Block for r in task) and (len({id(r) for r in task}) > 1) == interleaved
    lists = worker._block_runs("sil", runs, task)
    assert isinstance(lists.traces, dict) != interleaved
    assert lists.metric_trees is not None and lists.metrics is None  # each block's metrics in its column trees
    # one block's: its metrics' typed columns straight from its trees; two blocks': from the runs' dicts made of them
    assert (block_columns.tree_named(lists.metric_trees, len(ids)) is None) == interleaved
    made = encode_runs(ids, lists, campaign=campaign.name)
    records = [with_inputs(r, run, kind="sil") for r, run in zip(worker._materialized(task), runs)]
    oracle = _table(encode_block(ids, records, campaign=campaign.name))
    table = _table(made)
    assert table.schema.equals(oracle.schema, check_metadata=True)
    for name in oracle.column_names:
        if name not in (*METRIC_COLUMNS, *RECORD_COLUMNS) or not interleaved:
            assert table.column(name).equals(oracle.column(name)), name
    compact = {"sort_keys": True, "separators": (",", ":")}  # json's own text of each run's metrics and record
    rest = [{k: v for k, v in r.items() if k not in (*ROW_KEYS, "trace", "reason")} | {"id": i}
            for i, r in zip(ids, records)]  # fmt: skip
    assert record_texts(table) == record_texts(oracle) == [json.dumps(r, **compact) for r in rest]
    assert metric_texts(table) == metric_texts(oracle) == [json.dumps(r["metrics"], **compact) for r in records]
    store = Store(tmp_path / "s", campaign=campaign.name)
    store.put_block(made)
    for run_id, record in zip(ids, records):
        assert store.record(run_id) == json.loads(json.dumps({k: v for k, v in record.items() if k != "trace"})) | {
            "id": run_id
        }


def _verdicts_by_run(verdicts) -> list[tuple]:
    """Each planned run's verdict as :class:`~gainlink.hil.campaign.rows.Verdicts` holds it: status code, the names
    of the criteria it failed (its bits decoded), IAE, model mismatch and warning, its outputs' names and its texts."""
    out = []
    for u in range(len(verdicts.uids)):
        failed = sorted(name for bit, name in enumerate(verdicts.criteria) if verdicts.failed[u] >> bit & 1)
        shape = verdicts.shapes[verdicts.shape[u]] if verdicts.at[u] >= 0 else None
        numbers = (repr(float(verdicts.iae[u])), repr(float(verdicts.model[u])))  # NaN equal to NaN
        out.append((int(verdicts.code[u]), failed, numbers, bool(verdicts.warning[u]), shape, verdicts.text(u)))
    return out


def test_blocks_judged_where_they_ran_are_the_verdicts_judged_here_and_a_record_stored_again_judges_anew(
    tmp_path, monkeypatch
):
    """Each block file judged from its bytes (as the worker that made it judges it) and filed in, in another order than
    the store's: the same verdicts, texts and numbers as the store's files judged here, and nothing read from the store
    to complete them. A run stored again afterwards (a later error record: the one the store keeps) makes the verdicts
    judged ahead not the store's, whatever order they were filed in: they are all judged again, the run's the new
    record's."""
    from gainlink.hil.campaign.judged import judge_part
    from gainlink.hil.campaign.rows import Verdicts, plan_ids
    from gainlink.hil.campaign.store import block_report_part

    plan, store, records = _stored(tmp_path)
    ids, criteria = plan_ids(plan), plan.campaign.criteria
    here = Verdicts(criteria, ids).complete(store)
    expected = _verdicts_by_run(here)
    here.close()
    judged = {path.name: judge_part(block_report_part(path.read_bytes()), criteria) for path in store.files()}
    ahead = Verdicts(criteria, ids)
    for name in reversed(list(judged)):
        ahead.add(name, judged[name])
    with monkeypatch.context() as patch:
        patch.setattr(Store, "report_part", lambda *a, **k: pytest.fail("a block judged ahead read again"))
        ahead.complete(store)
    assert _verdicts_by_run(ahead) == expected
    assert {"pass", "fail", "error"} <= {("pass", "fail", "error", "missing")[c] for c, *_ in expected}
    ahead.close()

    again = next(p for p in plan.runs if records[p.id]["status"] == "error")
    store.put([again], kind="sil", results=[{"status": "error", "reason": "stored again"}])
    (new,) = set(store.files()) - {store.blocks / name for name in judged}
    redone = Verdicts(criteria, ids)
    redone.add(new.name, judge_part(block_report_part(new.read_bytes()), criteria))  # the later file filed in first
    for name, part in judged.items():
        redone.add(name, part)
    fresh = Verdicts(criteria, ids).complete(store)
    assert _verdicts_by_run(redone.complete(store)) == _verdicts_by_run(fresh) != expected
    u = int(np.searchsorted(redone.uids, again.id.encode()))
    assert "stored again" in redone.text(u)[0]
    redone.close()
    fresh.close()
