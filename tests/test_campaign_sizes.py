"""How a SIL campaign's runs are cut into Dask tasks (:func:`~gainlink.hil.campaign.runner.batch_sizes`)."""

from __future__ import annotations

import heapq

import pytest
from gainlink.hil.campaign.runner import MAX_BLOCK, batch_sizes


def _makespan(sizes: list[int], threads: int) -> int:
    """The runs the busiest thread steps when each block, in submission order, goes to the thread that frees first
    (as Dask hands a waiting task to the worker that asks), every run costing the same."""
    loads = [0] * threads
    for size in sizes:
        heapq.heapreplace(loads, loads[0] + size)
    return max(loads)


@pytest.mark.parametrize("threads", [1, 2, 3, 4])
@pytest.mark.parametrize("runs", [1, 7, 999, 4002, 10002, 100002])
def test_blocks_cover_the_runs_within_the_block_limit_and_leave_no_thread_a_last_block_alone(runs, threads):
    sizes = batch_sizes("sil", runs, threads)
    assert sum(sizes) == runs and max(sizes) <= MAX_BLOCK and min(sizes) >= 1
    assert max(sizes) - min(sizes) <= 1  # the runs shared evenly
    # the busiest thread steps at most its even share plus one run a block it takes: 5 blocks of 800 on 2 threads
    # would give one thread 2,400 runs of 4,002 while the other waits
    rounds = -(-len(sizes) // threads)
    assert _makespan(sizes, threads) <= -(-runs // threads) + rounds


def test_hil_runs_one_a_task_and_a_fixed_batch_is_kept():
    assert batch_sizes("hil", 5, 2) == [1] * 5
    assert batch_sizes("sil", 7, 2, batch=3) == [3, 3, 1]
