"""The block benchmark's own arithmetic (bench/campaign.py), against independent oracles: the machinery a run adds
fitted through campaigns of three sizes (scipy's linear regression), and the 2-over-1 ceiling and its pairs (sums by
hand). The benchmark's figures are the issue's targets, so the numbers it derives them by are tested here."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("campaign_bench", ROOT / "bench" / "campaign.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _campaigns(sizes: list[int], per_run_ms: float, fixed_s: float, own_ms: float, seed: int) -> list[dict]:
    """2-worker campaigns whose machinery CPU lies on a known line, with noise of a few tenths of a second in the
    fixed part (what the host does between campaigns)."""
    rng = np.random.default_rng(seed)
    out = []
    for n in sizes:
        machinery = fixed_s + per_run_ms * 1e-3 * n + rng.normal(0, 0.2)
        parts = {
            "workers_outside_runs": 0.7 * machinery,
            "client_until_stored": 0.2 * machinery,
            "report": 0.1 * machinery,
        }
        own = own_ms * 1e-3 * n * (1 + rng.normal(0, 0.05))
        out.append({"runs": n, "machinery_cpu_s": machinery, "machinery_parts_cpu_s": parts, "runs_own_cpu_s": own,
                    "workers_kernel_cpu_s": 0.0})  # fmt: skip
    return out


def test_the_machinery_fit_is_scipys_regression_over_the_largest_campaigns_own_cpu(bench):
    sizes = [4002] * 4 + [10002] * 4 + [100002] * 2
    campaigns = _campaigns(sizes, per_run_ms=0.07, fixed_s=0.9, own_ms=0.75, seed=3)
    fit = bench.machinery_fit(campaigns)
    oracle = stats.linregress([c["runs"] for c in campaigns], [c["machinery_cpu_s"] for c in campaigns])
    own = np.mean([c["runs_own_cpu_s"] for c in campaigns if c["runs"] == 100002]) / 100002
    assert fit["from_runs"] == [4002, 10002, 100002] and fit["campaigns"] == 10
    assert fit["per_run_ms"] == pytest.approx(1e3 * oracle.slope, abs=1e-4)
    assert fit["per_run_ratio"] == pytest.approx(oracle.slope / own, abs=1e-4)
    assert fit["per_run_ratio_stderr"] == pytest.approx(oracle.stderr / own, abs=1e-4)
    assert fit["fixed_s"] == pytest.approx(oracle.intercept, abs=0.01)
    # the known line is found within its error: 0.07 ms over 0.75 ms a run
    assert abs(fit["per_run_ratio"] - 0.07 / 0.75) < 4 * fit["per_run_ratio_stderr"] + 0.005


def test_the_fit_holds_where_a_slope_between_two_small_sizes_swings(bench):
    """The same line, noise drawn anew: the slope between the 4,002- and 10,002-run means moves by several hundredths
    of the runs' own CPU from draw to draw, the fit through the three sizes by a few thousandths."""
    sizes = [4002] * 4 + [10002] * 4 + [100002] * 2
    fits, slopes = [], []
    for seed in range(12):
        campaigns = _campaigns(sizes, per_run_ms=0.07, fixed_s=0.9, own_ms=0.75, seed=seed)
        fits.append(bench.machinery_fit(campaigns)["per_run_ratio"])
        small, ten = campaigns[:4], campaigns[4:8]
        slopes.append(bench.machinery_split(small, ten)["per_run_ratio"])
    assert np.ptp(slopes) > 0.03 and np.ptp(fits) < 0.015


def test_the_ceiling_sums_each_side_and_gives_each_pair_its_own(bench):
    walls = [{"processes": 1, "wall_s": 3.5}, {"processes": 2, "wall_s": 1.75},
             {"processes": 2, "wall_s": 2.0}, {"processes": 1, "wall_s": 3.0}]  # fmt: skip
    ceiling = bench.plain_ceiling(walls)
    assert ceiling["one_process_s"] == 6.5 and ceiling["two_processes_s"] == 3.75
    assert ceiling["speedup_2_vs_1"] == round(6.5 / 3.75, 3)
    assert ceiling["speedup_2_vs_1_by_pair"] == [2.0, 1.5]  # 3.5 / 1.75, then 3.0 / 2.0 (the pair 2-1 read in order)
