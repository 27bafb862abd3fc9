"""The report's scatter plot at a bounded cost: of more than ``cap`` runs of a status only every k-th in plan order
is drawn, the legend still counts every run and the title says what was drawn.

Oracles: the markers of each status's line in the figure against the runs picked here by slicing the runs of that
status in plan order with the step worked out by hand (257 passed runs at a cap of 100: every 3rd, 86 drawn; 43 failed
at a cap of 20: every 3rd, 15 drawn), and the counts of each status by hand.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from gainlink.hil.campaign import figures as figures_module
from gainlink.hil.campaign import report

RUNS = 300


def _tally() -> SimpleNamespace:
    """300 runs with an IAE in plan order, every 7th failed (43 failed, 257 passed); their IAE the run's number + 1
    and two numeric axes (the second the run's number, the first its negative), so a marker names its run."""
    k = np.arange(RUNS)
    return SimpleNamespace(
        axes=["a", "b", "word"],
        numeric={"a": True, "b": True, "word": False},
        scatter_iae=k + 1.0,
        scatter_fail=k % 7 == 0,
        scatter={"a": -k.astype(float), "b": k.astype(float), "word": np.full(RUNS, np.nan)},
    )


def _drawn(monkeypatch, cap: int) -> object:
    figures = []
    monkeypatch.setattr(figures_module, "png_bytes", lambda fig: figures.append(fig) or b"")
    monkeypatch.setattr(report, "SCATTER_RUNS", cap)
    plan = SimpleNamespace(campaign=SimpleNamespace(name="c"), artifacts={})
    report.scatter_figure(plan, _tally()).png()
    (fig,) = figures
    return fig


@pytest.mark.parametrize(
    ("cap", "pass_every", "fail_every", "title"),
    [
        (2000, 1, 1, "c: IAE against the varied parameters (x: failed)"),
        (257, 1, 1, "c: IAE against the varied parameters (x: failed)"),
        (100, 3, 1, "c: IAE against the varied parameters (x: failed)\n"
                    "drawn: 86 of 257 passed, every 3rd in plan order"),
        (20, 13, 3, "c: IAE against the varied parameters (x: failed)\n"
                    "drawn: 20 of 257 passed, every 13th in plan order; 15 of 43 failed, every 3rd in plan order"),
    ],
)  # fmt: skip
def test_the_scatter_draws_every_kth_run_of_each_status_in_plan_order(monkeypatch, cap, pass_every, fail_every, title):
    """Each numeric axis' panel draws runs 0, k, 2k, ... of each status in plan order (all of them below the cap),
    its legend counts every run of the status, and the title says what was left out."""
    fig = _drawn(monkeypatch, cap)
    passed = [k for k in range(RUNS) if k % 7][::pass_every]
    failed = [k for k in range(RUNS) if not k % 7][::fail_every]
    assert fig._suptitle.get_text() == title
    panels = [ax for ax in fig.axes if ax.lines]
    assert [ax.get_xlabel() for ax in panels] == ["a", "b"]
    for ax, sign in zip(panels, (-1, 1)):
        lines = {line.get_label(): line for line in ax.lines}
        assert set(lines) == {"fail (43)", "pass (257)"}
        for label, runs in (("fail (43)", failed), ("pass (257)", passed)):
            np.testing.assert_array_equal(lines[label].get_ydata(), np.array(runs) + 1.0)
            np.testing.assert_array_equal(lines[label].get_xdata(), sign * np.array(runs, float))
