"""What a closed-loop run feeds its plant and controller, fixed before the first step (and before any firmware is
built or peer started), and the per-step record it fills: one :class:`~.metrics.RunTrace` for every law and
endpoint (:mod:`.closed_loop`).
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass

import numpy as np
from gainlink.errors import ScenarioError
from gainlink.shipping.artifact import Artifact

from ..plants.base import Plant
from .metrics import RunTrace
from .scenario import Scenario, profile_values
from .twins import Twins


@dataclass(frozen=True)
class Plan:
    """Everything a run feeds the plant and the link, fixed before the first step.

    ``S`` holds the external scheduling signals per step (N, e: none for a law without them), ``sigma0`` the sigma
    the run starts at (NaN for a law without one).
    """

    N: int
    t: np.ndarray
    R: np.ndarray  # references (N, q)
    noise: np.ndarray  # measurement noise (N, p)
    D: np.ndarray  # input disturbances (N, m)
    S: np.ndarray  # external scheduling signals (N, e)
    sigma0: float
    silent_at: int | None
    crash_at: int | None
    period_s: float
    realtime: bool


def external_signals(scenario: Scenario, *, names: tuple[str, ...], t: np.ndarray) -> np.ndarray:
    """The external scheduling signals per step (N, e) from ``[schedule_signal.NAME]``, for the law's ``names``;
    one line when one is missing or a profile names none of them."""
    for name in scenario.schedule_signal:
        if name not in names:
            raise ScenarioError(
                f"scenario: schedule_signal.{name} is not an external scheduling signal of the artifact "
                f"(external: {', '.join(names) or 'none'})"
            )
    missing = [n for n in names if n not in scenario.schedule_signal]
    if missing:
        raise ScenarioError(f"scenario: the artifact is scheduled on {', '.join(missing)}: give [schedule_signal.NAME]")
    return np.column_stack([profile_values(scenario.schedule_signal[n], t) for n in names] or [np.zeros((t.size, 0))])


def plan_run(scenario: Scenario, *, law, artifact: Artifact, plant: Plant) -> Plan:
    """References, noise (from the scenario's seed), disturbances, external scheduling signals and peer faults per
    step, for ``plant`` just reset: the run starts at the sigma its first sample gives (``law.sigma_of``), and a
    reference without a profile holds the law's trim there (``law.r_op``)."""
    a = artifact
    Ts = a.Ts
    N = int(round(scenario.duration / Ts))
    realtime = scenario.mode == "realtime"
    t = np.arange(N) * Ts
    S = external_signals(scenario, names=law.externals(a), t=t)
    follow = getattr(plant, "schedule", None)  # a plant whose dynamics follow the external signals
    if N and follow is not None:
        follow(S[0])
    sigma0 = law.sigma_of(a, plant.outputs(), S[0] if N else np.zeros(S.shape[1]))
    r_op = law.r_op(a, sigma=sigma0)
    R = np.tile(r_op, (N, 1))  # absolute: the trim unless a profile says otherwise
    for j, name in enumerate(a.signals["references"]):
        if name in scenario.reference:
            R[:, j] = profile_values(scenario.reference[name], t, base=float(r_op[j]))
    noise = _noise(scenario, plant=plant, N=N, p=a.p)
    D = np.zeros((N, a.m))
    for d in scenario.disturbances:
        D[(t >= d.start) & (t < d.stop), plant.input_names.index(d.input)] += d.value
    silent_at = min((int(round(f.start / Ts)) for f in scenario.faults if f.kind == "silent"), default=None)
    crash_at = min((int(round(f.start / Ts)) for f in scenario.faults if f.kind == "crash"), default=None)
    period = scenario.period if (realtime and scenario.period) else Ts
    return Plan(N=N, t=t, R=R, noise=noise, D=D, S=S, sigma0=sigma0, silent_at=silent_at, crash_at=crash_at,
                period_s=period, realtime=realtime)  # fmt: skip


def _noise(scenario: Scenario, *, plant: Plant, N: int, p: int) -> np.ndarray:
    """The run's measurement noise per step (N, p), drawn from its own seed: each draw times its output's standard
    deviation, multiplied in place over the flat draws (numpy broadcasting a (N, 2) array by a (2,) row loops over
    pairs, ~5x slower; the same products)."""
    noise_sd = tuple(float(scenario.noise.get(name, 0.0)) for name in plant.output_names)
    if not any(noise_sd):
        return np.zeros((N, p))
    draws = np.random.default_rng(scenario.seed).standard_normal(N * p)  # the (N, p) draws in their order
    draws *= _tiled(noise_sd, N)
    return draws.reshape(N, p)


@functools.lru_cache(maxsize=4)
def _tiled(row: tuple[float, ...], N: int) -> np.ndarray:
    """``row`` repeated ``N`` times, flat and read-only (a campaign block's runs share one)."""
    out = np.tile(np.array(row), N)
    out.flags.writeable = False
    return out


PLANNED = ("duration", "mode", "period", "reference", "schedule_signal", "noise", "disturbances", "faults")
"""The scenario's fields :func:`plan_run` reads besides its seed (and the plant's start)."""


def plans_alike(scenario: Scenario, other: Scenario) -> bool:
    """Whether :func:`plan_run` plans ``scenario`` as ``other`` but for its seed (:func:`plan_like`). A field that
    is the same object is not compared (a campaign block's scenarios share their tables)."""
    return all(_same(getattr(scenario, name), getattr(other, name)) for name in PLANNED)


def _same(a, b) -> bool:
    return a is b or a == b


def plan_like(plan: Plan, scenario: Scenario, *, law, artifact: Artifact, plant: Plant) -> Plan:
    """The plan of ``scenario`` for ``plant`` just reset, when ``plan`` is that of a run whose scenario differs from
    it only in its seed and its plant's drawn numbers (a campaign block's runs): ``plan`` with the run's own noise,
    its references, disturbances, signals and times shared (the same arrays, made read-only), what
    :func:`plan_run` gives it bit for bit. :func:`plan_run` itself when the run starts elsewhere (another sigma)
    or its plant follows the external signals."""
    if not plan.N or getattr(plant, "schedule", None) is not None:
        return plan_run(scenario, law=law, artifact=artifact, plant=plant)
    sigma0 = law.sigma_of(artifact, plant.outputs(), plan.S[0])
    if struct.pack("d", sigma0) != struct.pack("d", plan.sigma0):  # the same bits, NaN included
        return plan_run(scenario, law=law, artifact=artifact, plant=plant)
    for shared in (plan.t, plan.R, plan.D, plan.S):
        if shared.flags.writeable:  # made read-only by the first run that shares it
            shared.flags.writeable = False
    # a shallow copy through the instance's dict: dataclasses.replace re-runs the fields' __init__ (~18 us a run),
    # copy.copy goes through __reduce_ex__ (~5.5 us); this ~1.4 us, the same fields (a frozen dataclass, no slots)
    out = object.__new__(Plan)
    out.__dict__.update(plan.__dict__, noise=_noise(scenario, plant=plant, N=plan.N, p=artifact.p))
    return out


def saturated(bits: np.ndarray, m: int) -> np.ndarray:
    """The saturation flags of ``bits`` (..., bit j: input j saturated) as bools (..., m), one input at a time: numpy
    broadcasting ``bits[..., None]`` against the m bits loops over a last axis of m (1 for the pendulum) at every
    record, 2-4x slower over a block's (1000, 1000) bits."""
    out = np.empty((*bits.shape, m), dtype=bool)
    for j in range(m):
        np.not_equal(bits & (1 << j), 0, out=out[..., j])
    return out


class Recorder:
    """The per-step arrays of a run, filled as it goes; :meth:`trace` cuts them to the steps taken."""

    def __init__(self, plan: Plan, *, artifact: Artifact, plant: Plant, allocate: bool = True) -> None:
        N, a = plan.N, artifact
        self.plan = plan
        self.SAT: np.ndarray | None = None  # the saturation flags as bools (N, m), when a campaign block made them
        if not allocate:  # a campaign block's run: its arrays are views of the block's record, set by the block
            return
        self.Y = np.zeros((N, a.p))
        self.U = np.zeros((N, a.m))
        self.SATBITS = np.zeros(N, dtype=np.int64)  # bit j: input j saturated
        self.GOT = np.zeros(N, dtype=bool)
        self.LAT = np.full(N, np.nan)
        self.SENT = np.full(N, np.nan)  # when sample k was sent, ns from the run start (NaN: never sent)
        self.BACK = np.full(N, np.nan)  # when its command came back, in time or late (NaN: never)
        self.TICK = np.zeros(N)
        self.DUE = np.full(N, np.nan)
        self.FLAGS = np.zeros(N, dtype=np.int64)
        self.SIGMA = np.full(N, np.nan)
        self.NAN = np.zeros(N, dtype=bool)  # the sample went out as NaN (a nan fault)
        self.X = np.full((N, len(plant.state_names)), np.nan)

    def trace(self, steps: int, *, law, artifact: Artifact, twins: Twins) -> RunTrace:
        """The recorded run up to ``steps``, with its twins (NaN columns without the closed-loop twin; None without
        the model twin)."""
        p = self.plan
        tw, mt = twins.twin, twins.model

        def nan(width: int) -> np.ndarray:
            return np.full((steps, width), np.nan)

        def cut(a: np.ndarray) -> np.ndarray:  # the array itself when it holds just the steps: the runs of a block
            return a if len(a) == steps else a[:steps]  # that share one (a plan's times) give that one object

        z = None if tw is None else tw.integrators(law, artifact)
        return RunTrace(
            t=cut(p.t),
            y=cut(self.Y),
            r=cut(p.R),
            s=cut(p.S),
            u=cut(self.U),
            sat=saturated(self.SATBITS[:steps], self.U.shape[1]) if self.SAT is None else cut(self.SAT),
            got=cut(self.GOT),
            latency_ns=cut(self.LAT),
            tick_ns=cut(self.TICK),
            deadline_ns=cut(self.DUE),
            x=cut(self.X),
            flags=cut(self.FLAGS),
            sigma=cut(self.SIGMA),
            nan_sent=cut(self.NAN),
            twin_y=tw.y if tw else nan(self.Y.shape[1]),
            twin_u=tw.u if tw else nan(self.U.shape[1]),
            twin_z=z if z is not None else nan(p.R.shape[1]),
            model_y=mt.y if mt else None,
            model_u=mt.u if mt else None,
        )


def describe_artifact(law, artifact: Artifact, path) -> dict:
    """What a report says about the artifact: identity and path, the law (``law.describe``: the compensator's
    stability, the model's provenance, a schedule, units)."""
    return {"name": artifact.name, "sha256": artifact.sha256, "path": str(path), **law.describe(artifact)}


def describe_plant(plant: Plant) -> dict:
    """What a report says about the plant: its signals and, for an FMU, the interface that ran and why."""
    from ..plants.fmu_interface import describe_interface

    return {
        "name": plant.name,
        "inputs": list(plant.input_names),
        "outputs": list(plant.output_names),
        "states": list(plant.state_names),
        **describe_interface(plant),
    }
