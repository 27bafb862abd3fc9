"""The campaign report's two figures, drawn from plain data: what they show is gathered by :mod:`.report` (from the
plan, the tally and the store), what is here needs neither, so a figure can be drawn wherever matplotlib is, a
cluster's worker included (:meth:`EnvelopeFigure.png`, :meth:`ScatterFigure.png`: picklable, each a few hundred kB
at most).

- :class:`EnvelopeFigure`: percentiles of every output and command over time (``envelopes.png``);
- :class:`ScatterFigure`: each run's IAE against each numeric axis, failed runs marked (``scatter.png``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from gainlink.proof.twin_plot import png_bytes


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def ordinal(n: int) -> str:
    """``2nd``, ``5th``, ``11th``, ``21st``."""
    last = "th" if n % 100 in (11, 12, 13) else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{last}"


@dataclass(frozen=True)
class EnvelopeFigure:
    """``envelopes.png``: the campaign's ``name``, its envelope bands (:func:`.envelopes.envelope_bands`; ``None``
    without a finished run) and its signals' names and units (``outputs``, ``inputs``, ``units``)."""

    name: str
    bands: dict | None
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    units: dict

    def png(self) -> bytes:
        """The figure as PNG: one panel a signal (outputs then commands), the 5-95 and 25-75 % bands, the median and
        the failed runs' median dashed; the title and the legend (the first panel's: the same in each) say which runs
        when not all are drawn."""
        bands = self.bands
        outs, ins = (bands["outputs"], bands["inputs"]) if bands is not None else (0, 0)
        panels = max(outs + ins, 1)
        fig, axes = _pyplot().subplots(panels, 1, figsize=(9, 2.3 * panels), sharex=True, squeeze=False)
        if bands is None:
            axes[0, 0].text(0.5, 0.5, "no finished run", ha="center", transform=axes[0, 0].transAxes)
            return png_bytes(fig)
        t = bands["t"]
        for i in range(outs + ins):
            ax = axes[i, 0]
            key, j = ("y", i) if i < outs else ("u", i - outs)
            pct = bands["percentiles"][:, :, i]
            ax.fill_between(t, pct[0], pct[4], alpha=0.2, color="C0", label="5-95 %")
            ax.fill_between(t, pct[1], pct[3], alpha=0.35, color="C0", label="25-75 %")
            ax.plot(t, pct[2], color="C0", lw=1.2, label="median")
            if bands["failed"]:
                ax.plot(t, bands["failed_median"][:, i], "--", color="C3", lw=1, label=_failed_label(bands))
            names = self.outputs if key == "y" else self.inputs
            name = names[j] if j < len(names) else f"{key}{j}"
            unit = self.units.get(name)
            ax.set_ylabel(f"{name} [{unit}]" if unit else name)
            ax.grid(True, alpha=0.3)
            if i == 0:  # the same entries in every panel: said once
                ax.legend(loc="best", fontsize=7)
        axes[-1, 0].set_xlabel(f"t [{self.units.get('time', 's')}]")
        fig.suptitle(f"{self.name}: {_envelope_scope(bands)}")
        return png_bytes(fig)


def _envelope_scope(bands: dict) -> str:
    """What the envelopes cover, for the title: every run, or which of the finished runs (on a second line)."""
    if bands["drawn"].draws is None:
        return f"outputs and commands over {bands['runs']} runs"
    drawn = bands["drawn"]
    which = (
        f"each grid point's first {drawn.draws} draws"
        if drawn.every == 1
        else f"every {ordinal(drawn.every)} run of the first draw in plan order"
    )
    return f"percentiles over {bands['runs']} of {bands['finished']} finished runs\n{which}"


def _failed_label(bands: dict) -> str:
    """The failed runs' median's legend: how many, and of how many failed runs when not all are drawn."""
    if bands["drawn"].draws is None:
        return f"median of {bands['failed']} failed"
    return f"median of {bands['failed']} of {bands['failed_of']} failed (those drawn)"


@dataclass(frozen=True)
class ScatterPanel:
    """One numeric axis' panel of ``scatter.png``: the axis' ``name``; by status (``"fail"``, ``"pass"``) the drawn
    runs' axis values and IAE (``x``, ``iae``) and how many runs of the status there are (``count``, for the legend);
    ``log``: the IAE axis logarithmic; ``empty``: the text drawn instead of markers (no finished run)."""

    name: str | None
    x: dict[str, np.ndarray]
    iae: dict[str, np.ndarray]
    count: dict[str, int]
    log: bool = False
    empty: str | None = None


@dataclass(frozen=True)
class ScatterFigure:
    """``scatter.png``: the campaign's ``name``, a panel an axis, the IAE axis' label and what the plot leaves out
    (``scope``: nothing, or a line a status drawn every k-th run)."""

    name: str
    panels: tuple[ScatterPanel, ...]
    ylabel: str
    scope: str

    def png(self) -> bytes:
        """The figure as PNG: up to three panels a row, the failed runs' markers crosses, the legend in the first."""
        n = len(self.panels)
        cols = min(n, 3)
        rows = math.ceil(n / cols)
        fig, grid = _pyplot().subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
        for k, panel in enumerate(self.panels):
            _draw_panel(grid[k // cols, k % cols], panel, self.ylabel, legend=k == 0)  # the same counts in each
        for k in range(n, grid.size):
            grid[k // cols, k % cols].axis("off")
        fig.suptitle(f"{self.name}: IAE against the varied parameters (x: failed){self.scope}")
        _margins(fig, title_lines=1 + self.scope.count("\n"))
        return png_bytes(fig)


Figure = EnvelopeFigure | ScatterFigure  # a report figure, drawn by its ``png()``


def png_of(figure: Figure) -> bytes:
    """``figure.png()``: what a cluster's task calls (the figure travels as data, the drawing is the worker's code)."""
    return figure.png()


_STYLES = {
    "fail": dict(color="C3", marker="x", markersize=4.7, alpha=0.8),
    "pass": dict(color="C0", marker="o", markersize=3.5, markeredgewidth=0, alpha=0.7),
}


def _draw_panel(ax: Any, panel: ScatterPanel, ylabel: str, *, legend: bool = True) -> None:
    """One scatter panel: each status's drawn runs as the markers of one line (not a scatter collection: a third of
    the drawing's time), the failed runs first; ``legend``: with the legend (the figure's first panel only: every
    panel's counts are the same, and each legend placed costs ~7 ms)."""
    if panel.empty is not None:
        ax.text(0.5, 0.5, panel.empty, ha="center", transform=ax.transAxes)
        return
    for status in ("fail", "pass"):
        if panel.count[status]:
            ax.plot(panel.x[status], panel.iae[status], linestyle="none", label=f"{status} ({panel.count[status]})",
                    **_STYLES[status])  # fmt: skip
    if panel.log:
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(_power_of_ten)
        ax.yaxis.set_minor_locator(_log_minor())
    ax.set_xlabel(panel.name)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if legend:
        ax.legend(fontsize=7)


def _log_minor() -> Any:
    """A log axis' minor ticks at 2 and 5 times each decade, not matplotlib's eight: each tick is a few artists made
    at every draw, and the eight were a fifth of the scatter plot's time (measured on the shipped pendulum's)."""
    from matplotlib.ticker import LogLocator

    return LogLocator(subs=(2, 5))


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def _power_of_ten(value: float, _pos: Any = None) -> str:
    """A log axis' tick label as plain text, ``10`` and a superscript exponent (the decades only, as matplotlib's
    own labels over more than a decade): its mathtext labels cost 0.3 s of parsing and layout per merge."""
    if not value > 0:
        return ""
    exponent = math.log10(value)
    if abs(exponent - round(exponent)) > 1e-9:
        return ""
    return "10" + str(round(exponent)).translate(_SUPERSCRIPT)


def _margins(fig: Any, *, title_lines: int = 1) -> None:
    """Fixed margins in inches for the tick labels, axis labels and title (of ``title_lines`` lines): ``tight_layout``
    measured every tick label's box, 40 % of the scatter plot's time for no visible gain."""
    w, h = fig.get_size_inches()
    top = 1 - (0.5 + 0.22 * (title_lines - 1)) / h
    fig.subplots_adjust(left=0.8 / w, right=1 - 0.2 / w, bottom=0.55 / h, top=top, wspace=0.35, hspace=0.45)
