"""A campaign's rows, one per planned run in plan order, made from the store when asked (``CampaignResult.rows``).

A row is what its planned point gives (:func:`.rows.point_row`: index, id, grid point, draw, axis values, seed,
artifact sha256), its verdict (:func:`.judged.verdict_head`: status, failed criteria, reasons; judged here by the
campaign's criteria over the block's typed columns, as the report judges them) and its stored record's row (complete,
measures, metrics, worker, the run's own reason: :func:`.block_texts.row_texts`). A run without a record is
:data:`.rows.MISSING_VERDICT`. Nothing holds every row: the rows are made a block file at a time as the walk in plan
order meets its runs, the last few files' rows kept (a block holds runs that follow each other in plan order but for
the grid points of another firmware build); ``rows[i]`` reads the one block file of run ``i``.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from typing import Any

from .criteria import evaluate_columns
from .judged import verdict_head
from .plan import CampaignPlan, PlannedRuns
from .rows import MISSING_VERDICT, point_row

BLOCKS_KEPT = 4  # block files whose rows a walk keeps: one block per firmware build the grid interleaves


class StoredRows(Sequence):
    """The rows of ``plan``'s runs (``len`` the planned runs) from ``store``, judged by the plan's criteria: iterate to
    walk them in plan order, ``rows[i]`` for one."""

    def __init__(self, plan: CampaignPlan, store: Any) -> None:
        self.plan, self.store = plan, store

    def __len__(self) -> int:
        return len(self.plan.runs)

    def __iter__(self) -> Iterator[dict]:
        blocks = _BlockRows(self.store, self.plan.campaign.criteria)
        heads = self.plan.runs.heads() if isinstance(self.plan.runs, PlannedRuns) else iter(self.plan.runs)
        for head in heads:
            yield point_row(head) | blocks.row(head.id)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        k = i + len(self) if i < 0 else i
        if not 0 <= k < len(self):
            raise IndexError(i)
        runs = self.plan.runs
        head = runs.head(k) if isinstance(runs, PlannedRuns) else runs[k]
        return point_row(head) | _BlockRows(self.store, self.plan.campaign.criteria).row(head.id)


class _BlockRows:
    """Each run's verdict and stored row by id, made a block file at a time, the last :data:`BLOCKS_KEPT` files'
    kept."""

    def __init__(self, store: Any, criteria: Any) -> None:
        self.store, self.criteria = store, criteria
        self.kept: OrderedDict[str, dict[str, dict]] = OrderedDict()

    def row(self, run_id: str) -> dict:
        hit = self.store.where(run_id)
        if hit is None:
            return {key: list(v) if isinstance(v, list) else v for key, v in MISSING_VERDICT.items()}
        if hit.name not in self.kept:
            self.kept[hit.name] = self._rows(hit)
            if len(self.kept) > BLOCKS_KEPT:
                self.kept.popitem(last=False)
        return self.kept[hit.name][run_id]

    def _rows(self, path: Any) -> dict[str, dict]:
        """The rows of the runs block file ``path`` holds the kept records of."""
        part = self.store.report_part(path, rows=True)
        if part is None:
            return {}
        failed = evaluate_columns(self.criteria, part.judged)
        return {
            run_id.decode("ascii"): verdict_head(part, i, failed[i]) | json.loads(part.rows[i])
            for i, run_id in enumerate(part.ids.tolist())
        }
