"""``gainlink analyze``: the structural analysis of a spec's plant, with the closed-loop bandwidth, compensator,
float32 and dead-time checks of the spec's own design when it designs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..errors import GainlinkError
from ..spec import PlantSpec
from .analysis import (
    Mode,
    complex_pairs,
    format_eigenvalue,
    is_stable,
    modes,
    pole_frequency,
    rank_and_cond,
    state_scaling,
    transmission_zeros,
)
from .margins import loop_bandwidth

SAMPLE_RATE_FACTOR = 10.0


@dataclass(frozen=True)
class AnalysisReport:
    """Everything ``gainlink analyze`` reports; ``to_dict`` gives the JSON form."""

    name: str
    kind: str
    n: int
    m: int
    p: int
    Ts: float
    open_loop_poles: list[complex]
    modes: list[Mode]
    controllability_rank: int
    controllability_cond: float
    observability_rank: int
    observability_cond: float
    stabilizable: bool
    detectable: bool
    transmission_zeros: list[complex]
    nonminimum_phase_zeros: list[complex]
    bandwidth_rad_s: float
    bandwidth_source: str
    sample_rate_ratio: float
    state_scale_ratio: float
    badly_scaled_states: list[str]
    warnings: list[str] = field(default_factory=list)
    compensator: dict | None = None  # the spec's designed compensator: poles, spectral radius, stability
    float32: dict | None = None  # float32 closed-loop fidelity of that design (gainlink.laws.lq.fidelity)
    dead_time: dict | None = None  # that design against the exact sampled dead times (gainlink.synthesis.deadtime)
    schedule: dict | None = None  # a scheduled spec: checks.schedule of its design (the plant above: first point)
    law_lines: list[str] = field(default_factory=list)  # what the spec's law adds (gainlink.laws.Law.analysis_lines)

    def to_dict(self) -> dict:
        """JSON-friendly dict; complex numbers become [re, im] pairs."""
        d = asdict(self)
        d["open_loop_poles"] = complex_pairs(self.open_loop_poles)
        d["transmission_zeros"] = complex_pairs(self.transmission_zeros)
        d["nonminimum_phase_zeros"] = complex_pairs(self.nonminimum_phase_zeros)
        d["modes"] = [dict(m.__dict__, eigenvalue=complex_pairs([m.eigenvalue])[0]) for m in self.modes]
        return d


def analyze(spec: PlantSpec, *, design: Callable[[PlantSpec], Any]) -> AnalysisReport:
    """Analyse a spec's plant; include the closed-loop bandwidth when the spec designs (with ``design``, the spec's
    law's design step: :func:`gainlink.laws.design`)."""
    import control

    plant = spec.plant
    A, B, C, D = plant.A, plant.B, plant.C, plant.D
    discrete = not plant.continuous
    n = plant.n
    c_rank, c_cond = rank_and_cond(control.ctrb(A, B), n)
    o_rank, o_cond = rank_and_cond(control.obsv(A, C), n)
    mode_list = modes(A, B, C, discrete=discrete)
    warnings = _mode_warnings(mode_list, c_rank=c_rank, c_cond=c_cond, n=n)
    zeros = transmission_zeros(A, B, C, D)
    nmp = [z for z in zeros if not is_stable(complex(z), discrete=discrete, margin=0.0)]
    if nmp:
        origin = " (from the Padé approximation of dead time)" if spec.plant.kind == "transfer_function" else ""
        warnings.append(
            f"non-minimum-phase zeros {', '.join(format_eigenvalue(z) for z in nmp)}{origin} limit bandwidth"
        )
    bandwidth, source, checks = _bandwidth(spec, warnings, design)
    ratio = (2 * np.pi / spec.Ts) / bandwidth if bandwidth > 0 else float("inf")
    if ratio < SAMPLE_RATE_FACTOR:
        warnings.append(
            f"sample rate is only {ratio:.1f}x the {source} bandwidth {bandwidth:.3g} rad/s "
            f"(want at least {SAMPLE_RATE_FACTOR:.0f}x: Ts <= {2 * np.pi / (SAMPLE_RATE_FACTOR * bandwidth):.3g} s)"
        )
    scale_ratio, bad_states = state_scaling(A, B, C, spec.plant.states)
    if bad_states:
        warnings.append(
            f"badly scaled states (balancing factors spread {scale_ratio:.2g}x): "
            f"{bad_states[0]} vs {bad_states[1]}; rescale units before design"
        )
    return AnalysisReport(
        name=spec.name,
        kind=spec.plant.kind,
        n=n,
        m=spec.plant.m,
        p=spec.plant.p,
        Ts=spec.Ts,
        open_loop_poles=[complex(z) for z in np.linalg.eigvals(A)],
        modes=mode_list,
        controllability_rank=c_rank,
        controllability_cond=c_cond,
        observability_rank=o_rank,
        observability_cond=o_cond,
        stabilizable=all(md.stable or md.controllable for md in mode_list),
        detectable=all(md.stable or md.observable for md in mode_list),
        transmission_zeros=[complex(z) for z in zeros],
        nonminimum_phase_zeros=[complex(z) for z in nmp],
        bandwidth_rad_s=bandwidth,
        bandwidth_source=source,
        sample_rate_ratio=float(ratio),
        state_scale_ratio=scale_ratio,
        badly_scaled_states=bad_states,
        warnings=warnings,
        compensator=checks.get("compensator"),
        float32=checks.get("float32"),
        dead_time=checks.get("dead_time"),
        schedule=checks.get("schedule"),
    )


def _mode_warnings(mode_list: list, *, c_rank: int, c_cond: float, n: int) -> list[str]:
    """Uncontrollable and unobservable modes (saying which are unstable), an ill-conditioned ctrb matrix."""
    warnings = []
    for md in mode_list:
        lam = format_eigenvalue(md.eigenvalue)
        if not md.controllable:
            warnings.append(f"mode {lam} is uncontrollable ({'stable' if md.stable else 'UNSTABLE'})")
        if not md.observable:
            warnings.append(f"mode {lam} is unobservable ({'stable' if md.stable else 'UNSTABLE'})")
    if c_rank == n and c_cond > 1e8:
        warnings.append(f"controllability matrix is ill-conditioned (cond {c_cond:.3g})")
    return warnings


def _bandwidth(spec: PlantSpec, warnings: list[str], design: Callable[[PlantSpec], Any]) -> tuple[float, str, dict]:
    """The closed-loop bandwidth of the spec's own design (and its checks), or the fastest open-loop pole
    when the spec does not design (saying why)."""
    try:
        result = design(spec)
    except GainlinkError as exc:
        warnings.append(f"design of this spec fails: {exc}")
        fastest = max(
            pole_frequency(z, discrete=not spec.plant.continuous, Ts=spec.Ts) for z in np.linalg.eigvals(spec.plant.A)
        )
        return fastest, "open loop", {}
    for w in (
        result.compensator.warning(),
        result.float32 and result.float32.warning(),
        result.dead_time and result.dead_time.warning(),
    ):
        if w:
            warnings.append(w)
    return (
        loop_bandwidth(result.margins, result.controller_poles, spec.Ts),
        "closed-loop (gain crossover)",
        result.artifact["checks"],
    )
