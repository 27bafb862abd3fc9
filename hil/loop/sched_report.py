"""The scheduled run's part of a report (:mod:`.report`): sigma per step (``sigma.csv``, ``sigma.png``) and the
summary's schedule line."""

from __future__ import annotations

from typing import Any

import numpy as np


def sigma_csv(trace: Any) -> str:
    """``t,sigma,held,clipped,rate`` per step: the sigma the law used and its flags (0/1)."""
    from gainlink.proof.scheduled_reference import SIGMA_CLIPPED, SIGMA_HELD, SIGMA_RATE

    flags = np.asarray(trace.sigma_flags, dtype=int)
    rows = ["t,sigma,held,clipped,rate"]
    for t, s, f in zip(trace.t, trace.sigma, flags):
        rows.append(f"{t:.9g},{s:.9g},{int(bool(f & SIGMA_HELD))},{int(bool(f & SIGMA_CLIPPED))},"
                    f"{int(bool(f & SIGMA_RATE))}")  # fmt: skip
    return "\n".join(rows) + "\n"


def sigma_plot(result: Any) -> bytes:
    """``sigma.png``: sigma against time, the schedule's points as lines, flagged steps marked."""
    import matplotlib.pyplot as plt
    from gainlink.proof.twin_plot import png_bytes

    tr, sch = result.trace, result.metrics["schedule"]
    fig, ax = plt.subplots(figsize=(8, 2.6))
    ax.plot(tr.t, tr.sigma, label=f"sigma ({sch['sigma']})")
    for v in sch["points"]:
        ax.axhline(v, color="0.6", lw=0.7, ls=":")
    flagged = np.asarray(tr.sigma_flags) != 0
    if flagged.any():
        ax.plot(tr.t[flagged], tr.sigma[flagged], "r.", ms=3, label="held / clipped / rate-limited")
    ax.set_xlabel("t [s]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"{result.scenario.name}: scheduling variable")
    return png_bytes(fig)


def schedule_lines(sch: dict | None) -> list[str]:
    """The summary's lines on sigma (nothing for an unscheduled run)."""
    if not sch:
        return []
    lo, hi = sch["points"][0], sch["points"][-1]
    return [
        f"  sigma {sch['sigma']} ({sch['source']}): covered [{sch['sigma_min']:.4g}, {sch['sigma_max']:.4g}] of "
        f"[{lo:.4g}, {hi:.4g}] ({100 * sch['coverage']:.0f}%), fastest {sch['max_rate']:.4g}/s"
        f" (rate_max {_rate(sch)}); steps held {sch['held_steps']},"
        f" clipped {sch['clipped_steps']}, rate-limited {sch['rate_limited_steps']}"
    ]


def _rate(sch: dict) -> str:
    """The law's rate_max with what covers it (a run recorded before ``rate_certified``: not certified)."""
    value = "none" if sch["rate_max"] is None else f"{sch['rate_max']:g}/s"
    return f"{value}, {'certified' if sch.get('rate_certified') else 'not certified'}"
