"""What ``gainlink design --plots DIR`` draws from an artifact, with python-control and matplotlib (Agg): the loop
broken at each actuator (a Bode plot with its gain and phase margins marked) and the closed loop's step response.

The broken loop is built here from the artifact alone (the design plant ``Ad, Bd, Cd, Dd`` and the unsaturated law
:meth:`~gainlink.shipping.artifact.Artifact.controller`, the other inputs' loops closed), and its margins are
python-control's (:func:`control.stability_margins`): an account of the design independent of the one its
``checks.margins`` holds (:mod:`.margins`), which each figure's title quotes beside them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

# the plotted frequency grid: four decades below Nyquist up to it; the margins are found on a finer and wider one
DECADES = 4.0
GRID_POINTS = 1200
MARGIN_DECADES = 6.0
MARGIN_GRID_POINTS = 3000  # python-control finds each crossing by interpolation: as exact as 20000 here, 20x cheaper
STEP_SECONDS_MIN = 10.0  # a step response at least this long, or long enough for the slowest closed-loop pole
STEP_MAX_SAMPLES = 5000


@dataclass(frozen=True)
class LoopMargins:
    """python-control's margins of one broken loop: every gain margin (as a factor, with its phase crossover in
    rad/s) and the smallest phase margin (degrees, at its gain crossover in rad/s)."""

    input: str
    gain_margins: tuple[tuple[float, float], ...]
    phase_margin_deg: float | None
    gain_crossover_rad_s: float | None


def broken_loop(artifact: Any, i: int) -> Any:
    """The loop gain ``L(z)`` at plant input ``i`` (negative-feedback convention: the loop closes as ``1 + L``),
    the other inputs' loops closed, as a discrete ``control.StateSpace``."""
    import control as ct

    a = artifact
    plant = ct.ss(a.Ad, a.Bd, a.Cd, a.Dd, a.Ts)
    law = a.controller()[:, : a.p]  # y -> u (the references held at zero)
    others = np.eye(a.m)
    others[i, i] = 0.0  # the other inputs stay closed, input i is cut
    closed = ct.feedback(law * plant, others, sign=1)
    return -closed[i, i]


def loop_margins(artifact: Any, i: int, loop: Any | None = None) -> LoopMargins:
    """python-control's gain and phase margins of :func:`broken_loop` at input ``i``, every crossing.

    Found on the loop's frequency response (``control.frd`` on a dense grid up to Nyquist): python-control's default
    for a state-space loop roots a polynomial of its order, and on the Wood-Berry column's 22 states it found eight
    gain crossovers where the response has one."""
    import control as ct

    loop = broken_loop(artifact, i) if loop is None else loop
    nyquist = np.pi / artifact.Ts
    w = np.logspace(np.log10(nyquist) - MARGIN_DECADES, np.log10(nyquist), MARGIN_GRID_POINTS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gm, pm, _, wpc, wgc, _ = ct.stability_margins(ct.frd(loop, w), returnall=True)
    gains = tuple(
        (float(g), float(w)) for g, w in sorted(zip(np.atleast_1d(gm), np.atleast_1d(wpc)), key=lambda gw: gw[1])
    )
    pm, wgc = np.atleast_1d(pm), np.atleast_1d(wgc)
    k = int(np.argmin(np.abs(pm))) if pm.size else None
    return LoopMargins(
        input=artifact.signals["inputs"][i],
        gain_margins=gains,
        phase_margin_deg=None if k is None else float(pm[k]),
        gain_crossover_rad_s=None if k is None else float(wgc[k]),
    )


def design_plots(artifact: Any) -> dict[str, bytes]:
    """``loop_<input>.png`` per plant input and ``step.png``, as PNG bytes (nothing written here)."""
    files = {}
    for i, name in enumerate(artifact.signals["inputs"]):
        files[f"loop_{name}.png"] = _png(_bode_figure(artifact, i))
    files["step.png"] = _png(_step_figure(artifact))
    return files


def _png(fig: Any) -> bytes:
    from gainlink.proof.twin_plot import png_bytes

    return png_bytes(fig)


def _bode_figure(artifact: Any, i: int) -> Any:
    """Magnitude (dB) and phase (degrees) of the broken loop against frequency (rad/s), each gain margin drawn at
    its phase crossover, the phase margin at the gain crossover, and the Nyquist frequency."""
    import control as ct
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = artifact
    per = f"rad/{a.unit('time')}"
    loop = broken_loop(a, i)
    m = loop_margins(a, i, loop)
    nyquist = np.pi / a.Ts
    w = np.logspace(np.log10(nyquist) - DECADES, np.log10(nyquist), GRID_POINTS)
    resp = ct.frequency_response(loop, w)
    mag_db = 20 * np.log10(np.abs(resp.magnitude))
    phase = np.degrees(np.unwrap(resp.phase))
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    ax_m.semilogx(w, mag_db, lw=1.2)
    ax_p.semilogx(w, phase, lw=1.2)
    ax_m.axhline(0.0, color="k", lw=0.8, ls=":")
    for k in range(int(np.floor(phase.min() / 360.0)) - 1, int(np.ceil(phase.max() / 360.0)) + 1):
        if phase.min() - 30 <= 180.0 + 360.0 * k <= phase.max() + 30:
            ax_p.axhline(180.0 + 360.0 * k, color="k", lw=0.8, ls=":")
    for gain, wpc in m.gain_margins:
        if not np.isfinite(gain) or gain <= 0:
            continue
        gm_db = 20 * np.log10(gain)
        ax_m.vlines(wpc, -gm_db, 0.0, colors="C3", lw=1.5)
        ax_m.annotate(f"GM {gm_db:+.1f} dB\nat {wpc:.3g} {per}", (wpc, -gm_db / 2), fontsize=8, color="C3",
                      xytext=(4, 0), textcoords="offset points")  # fmt: skip
        ax_p.axvline(wpc, color="C3", lw=0.8, ls="--")
    if m.phase_margin_deg is not None:
        wgc = m.gain_crossover_rad_s
        at = float(np.interp(np.log(wgc), np.log(w), phase))
        edge = 180.0 * np.sign(at) if at != 0 else -180.0
        ax_p.vlines(wgc, at, edge, colors="C2", lw=1.5)
        ax_p.annotate(f"PM {m.phase_margin_deg:.1f} deg\nat {wgc:.3g} {per}", (wgc, (at + edge) / 2), fontsize=8,
                      color="C2", xytext=(4, 0), textcoords="offset points")  # fmt: skip
        ax_m.axvline(wgc, color="C2", lw=0.8, ls="--")
    # a discrete loop's magnitude dives towards a zero at Nyquist (z = -1): keep the axis on the rest
    ax_m.set_ylim(max(float(mag_db.min()), float(np.percentile(mag_db, 3)) - 20.0) - 5.0, float(mag_db.max()) + 10.0)
    for ax in (ax_m, ax_p):
        ax.axvline(nyquist, color="0.5", lw=0.8, ls="-.")
        ax.grid(True, which="both", alpha=0.3)
    ax_m.set_ylabel("|L| [dB]")
    ax_p.set_ylabel("phase of L [deg]")
    ax_p.set_xlabel(f"frequency [{per}] (Nyquist {nyquist:.4g} {per})")
    fig.suptitle(f"{a.name}: the loop broken at input {m.input} (the others closed), L = -u/v\n"
                 f"{_design_margins(a, m.input)}", fontsize=10)  # fmt: skip
    return fig


def _design_margins(a: Any, name: str) -> str:
    """The design's own figures for input ``name`` (``checks.margins``), as ``design`` prints them."""
    row = next((r for r in a.checks.get("margins", []) if r["input"] == name), None)
    if row is None:
        return "design: no margins recorded"

    def db(v: float | None) -> str:
        return "beyond 60 dB" if v is None else f"{v:+.1f} dB"

    pm, per = row["phase_margin_deg"], f"rad/{a.unit('time')}"
    return f"design: gain margin {db(row['gain_margin_up_db'])} / {db(row['gain_margin_down_db'])}, " + (
        "no gain crossover" if pm is None else f"phase {pm:.1f} deg at {row['gain_crossover_rad_s']:.3g} {per}"
    )


def _step_figure(artifact: Any) -> Any:
    """The linear closed loop (design plant, unsaturated law) after a unit step of each reference (a regulator:
    of a disturbance added at each plant input): every output and command against time."""
    import control as ct
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = artifact
    cl = a.closed_loop()
    steps = list(a.signals["references"]) or [f"d_{u}" for u in a.signals["inputs"]]
    outputs = list(cl.output_labels)
    T = np.arange(0.0, _step_duration(a, cl), a.Ts)
    fig, axes = plt.subplots(len(outputs), 1, figsize=(8, 1.9 * len(outputs) + 1), sharex=True, squeeze=False)
    for name in steps:
        resp = ct.step_response(cl, T=T, input=cl.input_labels.index(name), squeeze=False)
        for k, ax in enumerate(axes[:, 0]):
            ax.step(resp.time, resp.outputs[k, 0], where="post", lw=1.2, label=f"step of {name}")
    for k, ax in enumerate(axes[:, 0]):
        kind = "command" if k >= a.p else "output"
        ax.set_ylabel(f"{a.label(outputs[k])} ({kind})")
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="best")
    axes[-1, 0].set_xlabel(f"t [{a.unit('time')}]")
    what = "reference" if a.signals["references"] else "input disturbance"
    fig.suptitle(f"{a.name}: the closed loop after a unit {what} step\n(design plant, linear law: no limits; "
                 "deviations from the operating point)", fontsize=10)  # fmt: skip
    return fig


def _step_duration(a: Any, cl: Any) -> float:
    """Long enough for the slowest closed-loop pole to decay to 1 % (at least :data:`STEP_SECONDS_MIN`)."""
    radius = float(np.max(np.abs(np.linalg.eigvals(cl.A)), initial=0.0))
    if not 0.0 < radius < 1.0:
        return STEP_SECONDS_MIN
    return float(min(max(STEP_SECONDS_MIN, a.Ts * np.log(0.01) / np.log(radius)), STEP_MAX_SAMPLES * a.Ts))
