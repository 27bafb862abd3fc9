"""The report's envelopes at a bounded cost: past ``cap`` finished runs only every k-th in plan order is read, the
failed runs' median by the same rule over the failed runs, and the figure says so.

Oracles: ``np.nanpercentile`` / ``np.nanmedian`` over the runs the rule names, picked here by slicing the runs in plan
order with the step worked out by hand (300 runs at a cap of 100: every 3rd; 43 failed runs at a cap of 20: every
3rd), within the half bin the function states, recomputed here from the extremes of the runs read.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.hil.campaign import report
from gainlink.hil.campaign.report import PERCENTILES, envelope_bands
from gainlink.hil.campaign.store import Store, encode_block, encode_trace

N = 40  # samples a trace


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


@pytest.mark.parametrize(
    ("cap", "every", "failed_every"),
    [(100, 3, 1), (20, 15, 3), (300, 1, 1)],
)
def test_the_bands_are_numpys_percentiles_over_every_kth_run_in_plan_order(tmp_path, cap, every, failed_every):
    """300 finished runs (43 failed) in three blocks: the percentiles are numpy's over runs 0, k, 2k, ... in plan
    order and the failed median numpy's over every k'-th failed run, each within half a bin; the counts name them."""
    ids, status, sig = _runs()
    store = _store(tmp_path, ids, sig, [110, 220])
    bands = envelope_bands(store, status, bins=256, cap=cap)
    chosen = ids[::every]
    failed = [i for i in ids if status[i] == "fail"][::failed_every]
    assert (bands["every"], bands["failed_every"], bands["finished"], bands["failed_of"]) == (
        every,
        failed_every,
        300,
        43,
    )
    assert (bands["runs"], bands["failed"]) == (len(chosen), len(failed))
    read = np.stack([sig[i] for i in sorted(set(chosen) | set(failed))]).astype(float)
    half = (np.nanmax(read, axis=0) - np.nanmin(read, axis=0)) / 256 / 2
    np.testing.assert_array_equal(bands["half_bin"], half)
    over = np.stack([sig[i] for i in chosen]).astype(float)
    for i, q in enumerate(PERCENTILES):
        assert _within_half_bin(bands["percentiles"][i], np.nanpercentile(over, q, axis=0), half), q
    bad = np.stack([sig[i] for i in failed]).astype(float)
    assert _within_half_bin(bands["failed_median"], np.nanmedian(bad, axis=0), half)
    if every > 1:  # the runs left out move the percentiles: the oracle tells the rule's runs from all of them
        everyone = np.stack(list(sig.values())).astype(float)
        assert not _within_half_bin(bands["percentiles"][2], np.nanpercentile(everyone, 50, axis=0), half / 8)


def test_the_same_runs_give_the_same_bands_however_they_are_stored(tmp_path):
    """The runs chosen are a rule of the plan order alone: the same 300 runs stored as one block, or as five blocks
    written in another order, give the same bands bit for bit (a run listed twice in the status counts once)."""
    ids, status, sig = _runs()
    one = envelope_bands(_store(tmp_path / "one", ids, sig, []), status, bins=256, cap=40)
    shuffled = [ids[k] for k in np.random.default_rng(3).permutation(len(ids))]
    other = envelope_bands(_store(tmp_path / "five", shuffled, sig, [60, 120, 180, 240]), status, bins=256, cap=40)
    assert one["every"] == 8 and one["runs"] == 38
    for key in ("percentiles", "failed_median", "half_bin", "t"):
        np.testing.assert_array_equal(one[key], other[key])
    assert {k: one[k] for k in ("runs", "failed", "every", "failed_every")} == {
        k: other[k] for k in ("runs", "failed", "every", "failed_every")
    }


def test_the_figure_names_the_runs_it_covers(tmp_path, monkeypatch):
    """Past the cap the title says how many of the finished runs the percentiles cover and which, and the failed
    median's legend how many of the failed; under it the title counts the runs, as before."""
    from types import SimpleNamespace

    ids, status, sig = _runs()
    store = _store(tmp_path, ids, sig, [150])
    drawn = []
    monkeypatch.setattr(report, "png_bytes", lambda fig: drawn.append(fig) or b"")
    plan = SimpleNamespace(campaign=SimpleNamespace(name="c"), artifacts={})
    for cap in (20, 2000):
        monkeypatch.setattr(report, "ENVELOPE_RUNS", cap)
        report.envelopespng_bytes(plan, status, store)
    past, under = drawn
    assert past._suptitle.get_text() == "c: percentiles over 20 of 300 finished runs, every 15th in plan order"
    assert "median of 15 of 43 failed, every 3rd" in [t.get_text() for t in past.axes[0].get_legend().get_texts()]
    assert under._suptitle.get_text() == "c: outputs and commands over 300 runs"
    assert "median of 43 failed" in [t.get_text() for t in under.axes[0].get_legend().get_texts()]
