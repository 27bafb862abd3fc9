"""The report's envelopes at a bounded cost: past ``cap`` finished runs only those of each grid point's first draws
are read, and of the block files only the row groups that hold them; the failed runs' median over the failed runs among
them, and the figure says so.

Oracles: ``np.nanpercentile`` / ``np.nanmedian`` over the runs the rule names, picked here by a loop over the number of
first draws (the most whose runs stay within the cap; worked out by hand too: 300 runs of 3 grid points of 100 draws,
every 7th failed, at a cap of 100: 33 draws, 99 runs, of them 5 + 4 + 5 = 14 failed (runs 0-28, 105-126 and 203-231 by
7); at a cap of 20: 6 draws, 18 runs, 3 failed (runs 0, 105 and 203)), within the half bin the function states,
recomputed here from the extremes of the runs read; the row groups read, recorded as Parquet is asked for them, against
those that hold a chosen run, from where the blocks were cut and the row group's size.
"""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest
from gainlink.hil.campaign import envelopes, figures, report
from gainlink.hil.campaign import store as store_module
from gainlink.hil.campaign.block_file import encode_block, folder_key
from gainlink.hil.campaign.block_layout import encode_trace
from gainlink.hil.campaign.envelopes import PERCENTILES, envelope_bands
from gainlink.hil.campaign.rows import RunStatus
from gainlink.hil.campaign.store import Store

N = 40  # samples a trace
DRAWS = 100  # draws a grid point: run k is draw k % 100 of grid point k // 100


def _runs(count: int = 300) -> tuple[list[str], dict[str, str], dict[str, np.ndarray]]:
    """``count`` runs in plan order: their ids, pass/fail (every 7th failed: 43 of 300) and stacked outputs and
    commands (N x 3, float32 as stored, NaN in one run)."""
    rng = np.random.default_rng(23)
    ids, status, sig = [], {}, {}
    for k in range(count):
        run_id = f"run-{k:04d}"
        y = rng.normal(np.sin(np.arange(N) * 0.1)[:, None] * (1 + k / 100), 0.3, (N, 2)).astype(np.float32)
        u = rng.standard_cauchy((N, 1)).astype(np.float32)
        if k == 9:
            y[3:6, 1] = np.nan
        ids.append(run_id)
        status[run_id] = "fail" if k % 7 == 0 else "pass"
        sig[run_id] = np.concatenate([y, u], axis=1)
    return ids, status, sig


def _status(status: dict[str, str], draws: list[int]) -> RunStatus:
    """``status`` as the report's tally gives it, each run's draw ``draws[k]``."""
    ids = np.array([i.encode() for i in status], dtype="S")
    return RunStatus(ids, np.array([v == "fail" for v in status.values()]), np.array(draws))


def _first_draws(draws: list[int], cap: int) -> list[bool]:
    """Which runs (of draws ``draws``) are those of the first D draws, D the most whose runs are at most ``cap``."""
    most = max(d for d in range(max(draws) + 2) if sum(x < d for x in draws) <= cap)
    return [x < most for x in draws]


def _store(folder, ids: list[str], sig: dict[str, np.ndarray], cuts: list[int]) -> Store:
    """The runs stored as blocks cut at ``cuts`` (each block's runs in the order given)."""
    store = Store(folder, campaign="c")
    for a, b in zip([0, *cuts], [*cuts, len(ids)]):
        part = ids[a:b]
        records = [
            {
                "status": "done",
                "trace": encode_trace(np.arange(N) * 0.1, sig[i][:, :2], sig[i][:, 2:], np.zeros((N, 0))),
            }
            for i in part
        ]
        store.put_block(encode_block(part, records, campaign="c"))
    return Store(folder)


def _within_half_bin(got: np.ndarray, want: np.ndarray, half: np.ndarray) -> bool:
    same_nan = np.array_equal(np.isnan(got), np.isnan(want))
    return same_nan and bool(np.all(np.abs(np.nan_to_num(got - want)) <= half * (1 + 1e-9)))


def _check_bands(bands: dict, sig: dict, chosen: list[str], failed: list[str], bins: int = 256) -> None:
    """The bands are numpy's percentiles over ``chosen`` and numpy's median over ``failed``, within half a bin (of
    ``bins`` a sample)."""
    assert (bands["runs"], bands["failed"]) == (len(chosen), len(failed))
    read = np.stack([sig[i] for i in sorted(set(chosen) | set(failed))]).astype(float)
    half = (np.nanmax(read, axis=0) - np.nanmin(read, axis=0)) / bins / 2
    np.testing.assert_array_equal(bands["half_bin"], half)
    over = np.stack([sig[i] for i in chosen]).astype(float)
    for i, q in enumerate(PERCENTILES):
        assert _within_half_bin(bands["percentiles"][i], np.nanpercentile(over, q, axis=0), half), q
    bad = np.stack([sig[i] for i in failed]).astype(float)
    assert _within_half_bin(bands["failed_median"], np.nanmedian(bad, axis=0), half)
    if len(chosen) < len(sig):  # the runs left out move the percentiles: the oracle tells the rule's runs from all
        everyone = np.stack(list(sig.values())).astype(float)
        assert not _within_half_bin(bands["percentiles"][2], np.nanpercentile(everyone, 50, axis=0), half / 8)


@pytest.mark.parametrize(
    ("cap", "draws", "runs", "failed"),
    [(100, 33, 99, 14), (20, 6, 18, 3), (300, None, 300, 43)],
)
def test_the_bands_are_numpys_percentiles_over_each_grid_points_first_draws(tmp_path, cap, draws, runs, failed):
    """300 finished runs of 3 grid points (43 failed) in three blocks: the percentiles are numpy's over each grid
    point's first D draws, D the most that keeps them within the cap, and the failed median numpy's over the failed
    runs among them, each within half a bin; the counts and the draws name them."""
    ids, status, sig = _runs()
    store = _store(tmp_path, ids, sig, [110, 220])
    draws_of = [k % DRAWS for k in range(300)]
    bands = envelope_bands(store, _status(status, draws_of), bins=256, cap=cap)
    chosen = [i for i, ok in zip(ids, _first_draws(draws_of, cap)) if ok]
    failed_ids = [i for i in chosen if status[i] == "fail"]
    assert (len(chosen), len(failed_ids)) == (runs, failed)  # the rule's runs, counted by hand
    assert (bands["drawn"].draws, bands["finished"], bands["failed_of"]) == (draws, 300, 43)
    _check_bands(bands, sig, chosen, failed_ids)


def test_past_the_cap_of_grid_points_every_kth_run_of_the_first_draw(tmp_path):
    """300 grid points of one draw each at a cap of 100: the first draw alone is over the cap, so every 3rd run in
    plan order, the failed median over the failed among them (every 21st run: 15); at a cap of 20 every 15th (the
    failed among them every 105th: 3)."""
    ids, status, sig = _runs()
    store = _store(tmp_path, ids, sig, [150])
    bands = envelope_bands(store, _status(status, [0] * 300), bins=256, cap=100)
    assert (bands["drawn"].draws, bands["drawn"].every) == (1, 3)
    _check_bands(bands, sig, ids[::3], ids[::21])
    few = envelope_bands(store, _status(status, [0] * 300), bins=256, cap=20)
    assert (few["drawn"].draws, few["drawn"].every, few["failed"]) == (1, 15, 3)
    _check_bands(few, sig, ids[::15], ids[::105])


def test_the_read_touches_only_the_row_groups_of_the_runs_drawn(tmp_path, monkeypatch):
    """300 runs in blocks of 10 (a row group each): at a cap of 20 (each grid point's first 6 draws, the failed median
    over the failed among them) Parquet is asked only for the row groups holding one of them, worked out from the cuts
    (each named here by its first run, read back from the file); under the cap, for every one. A block file is one row
    group."""
    ids, status, sig = _runs()
    cuts = list(range(0, 301, 10))
    store = _store(tmp_path, ids, sig, cuts[1:-1])
    assert {pq.ParquetFile(path).num_row_groups for path in store.files()} == {1}
    asked: list[str] = []
    iter_batches = pq.ParquetFile.iter_batches

    def spied(self, *args, row_groups=None, **kwargs):
        for g in range(self.num_row_groups) if row_groups is None else row_groups:
            asked.append(self.read_row_group(g, columns=["id"]).column("id")[0].as_py())
        return iter_batches(self, *args, row_groups=row_groups, **kwargs)

    monkeypatch.setattr(pq.ParquetFile, "iter_batches", spied)
    draws_of = [k % DRAWS for k in range(300)]
    envelope_bands(store, _status(status, draws_of), bins=256, cap=20)
    wanted = [k for k in range(300) if k % DRAWS < 6]
    assert sorted(asked) == [ids[k] for k in sorted({k // 10 * 10 for k in wanted})] and len(asked) == 3
    asked.clear()
    envelope_bands(store, _status(status, draws_of), bins=256, cap=300)
    assert sorted(asked) == ids[::10]


def test_a_block_file_of_many_runs_is_one_row_group(tmp_path):
    """A block of 300 runs (past store.TRACE_BATCH, the row group's size before layout 6) is one row group of 300
    rows, read from the file's Parquet metadata; its traces read back in batches are each run's own."""
    ids, _, sig = _runs()
    store = _store(tmp_path, ids, sig, [])
    (path,) = store.files()
    meta = pq.ParquetFile(path).metadata
    assert (meta.num_row_groups, meta.row_group(0).num_rows) == (1, 300) and store_module.TRACE_BATCH < 300
    seen = 0
    for names, stack in store.trace_stacks(ids[::-1], fields=("t", "y", "u")):
        for j, name in enumerate(names.tolist()):
            got = np.concatenate([stack["y"][j], stack["u"][j]], axis=1)
            np.testing.assert_array_equal(got, sig[name.decode()])
            seen += 1
    assert seen == 300


def test_the_same_runs_give_the_same_bands_however_they_are_stored(tmp_path):
    """The runs chosen are a rule of the plan alone: the same 300 runs stored as one block, or as five blocks
    written in another order, give the same bands bit for bit."""
    ids, status, sig = _runs()
    draws_of = [k % DRAWS for k in range(300)]
    one = envelope_bands(_store(tmp_path / "one", ids, sig, []), _status(status, draws_of), bins=256, cap=40)
    shuffled = [ids[k] for k in np.random.default_rng(3).permutation(len(ids))]
    five = _store(tmp_path / "five", shuffled, sig, [60, 120, 180, 240])
    other = envelope_bands(five, _status(status, draws_of), bins=256, cap=40)
    assert one["drawn"].draws == 13 and one["runs"] == 39
    for key in ("percentiles", "failed_median", "half_bin", "t"):
        np.testing.assert_array_equal(one[key], other[key])
    assert {k: one[k] for k in ("runs", "failed", "finished", "failed_of")} == {
        k: other[k] for k in ("runs", "failed", "finished", "failed_of")
    }


def test_the_figure_names_the_runs_it_covers(tmp_path, monkeypatch):
    """Past the cap the title says how many of the finished runs the percentiles cover and which, and the failed
    median's legend how many of the failed and which; under it the title counts the runs, as before."""
    from types import SimpleNamespace

    ids, status, sig = _runs()
    store = _store(tmp_path, ids, sig, [150])
    drawn = []
    monkeypatch.setattr(figures, "png_bytes", lambda fig: drawn.append(fig) or b"")
    plan = SimpleNamespace(campaign=SimpleNamespace(name="c"), artifacts={})
    for cap in (20, 2000):
        monkeypatch.setattr(envelopes, "ENVELOPE_RUNS", cap)
        report.envelope_figure(plan, _status(status, [k % DRAWS for k in range(300)]), store).png()
    past, under = drawn
    assert past._suptitle.get_text() == ("c: percentiles over 18 of 300 finished runs\neach grid point's first 6 draws")
    legend = [t.get_text() for t in past.axes[0].get_legend().get_texts()]
    assert "median of 3 of 43 failed (those drawn)" in legend
    assert under._suptitle.get_text() == "c: outputs and commands over 300 runs"
    assert "median of 43 failed" in [t.get_text() for t in under.axes[0].get_legend().get_texts()]


def test_a_runs_draw_is_its_place_among_its_grid_points_runs():
    """The draws the report's tally gives the envelopes (:func:`~.rows.plan_draws`) against each planned run's own
    draw, as the plan makes the run (3 grid points of 5 draws), and of a plan of points, the points' own."""
    from gainlink.hil.campaign import parse_campaign
    from gainlink.hil.campaign.plan import CampaignPlan, plan_campaign
    from gainlink.hil.campaign.rows import plan_draws
    from support.paths import EXAMPLES

    campaign = parse_campaign(
        {
            "name": "draws", "kind": "sil", "seed": 3, "runs": 5, "spec": str(EXAMPLES / "pendulum.toml"),
            "scenario": {"duration": 0.5, "plant": {"kind": "cart_pendulum"}},
            "grid": [{"target": "plant.parameters.m", "values": [0.8, 1.0, 1.2], "apply": "set"}],
            "draw": [{"target": "plant.parameters.M", "distribution": "uniform", "low": 0.7, "high": 1.3}],
        }
    )  # fmt: skip
    plan = plan_campaign(campaign)
    heads = list(plan.runs.heads())
    assert plan_draws(plan).tolist() == [h.draw for h in heads] == [0, 1, 2, 3, 4] * 3
    points = CampaignPlan(campaign=campaign, runs=tuple(plan.runs)[::-1])
    assert plan_draws(points).tolist() == [4, 3, 2, 1, 0] * 3


def test_a_stack_read_before_the_verdicts_gives_their_bands_and_refuses_a_run_they_did_not_choose(tmp_path):
    """The two steps apart, as a cluster's worker and the client take them: the runs' traces read and binned with no
    verdict (of a folder the worker sees: none from one it does not), then the verdicts' failed runs counted: numpy's
    percentiles, to the bit the one call's bands; a stack holding a run the verdicts did not choose (stored, not
    finished) is refused, not made into bands of other runs."""
    ids, status, sig = _runs()
    store = _store(tmp_path, ids, sig, [150])
    every = np.array([i.encode() for i in ids], dtype="S")
    verdicts = _status(status, [k % DRAWS for k in range(300)])
    request = envelopes.envelope_request(verdicts, cap=1000)
    key = folder_key(store.blocks)
    assert envelopes.cluster_stack((str(store.out), (key[0], key[1] + 1)), every) is None  # another machine's folder
    stack = envelopes.cluster_stack((str(tmp_path), key), every)
    bands = envelopes.stack_bands(stack, request)
    _check_bands(bands, sig, ids, [i for i in ids if status[i] == "fail"], bins=envelopes.ENVELOPE_BINS)
    whole = envelope_bands(store, verdicts, cap=1000)
    assert all(np.array_equal(bands[k], whole[k], equal_nan=True) for k in ("t", "percentiles", "failed_median"))
    assert (bands["runs"], bands["failed"], bands["finished"], bands["failed_of"]) == (300, 43, 300, 43)
    unfinished = dict(list(status.items())[1:])  # run 0 stored, its verdict not a finished run's
    fewer = envelopes.envelope_request(_status(unfinished, [k % DRAWS for k in range(1, 300)]), cap=1000)
    with pytest.raises(envelopes.StackMismatch):
        envelopes.stack_bands(stack, fewer)
