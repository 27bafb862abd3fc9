"""What a closed loop (:mod:`gainlink.hil.loop`: SIL, HIL, PIL, the twins, simulate) asks of a law beyond its step,
with the default of a law that has no scheduling variable and no check of its own: a mixin of
:class:`~gainlink.laws.base.Law`, each method answered by the law's family (``lq_run``, ``fixed_run``,
``fixed_pil``, ``scheduled_run``, ``scheduled_pil``). A method a law cannot answer refuses from its declaration
(``Law.refuse``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import LawError


class LoopHooks:
    """The loop-facing part of a law (module docstring); ``refuse`` and ``label`` are the law's."""

    label: str
    #: The scenario plant that is the law's own model of the plant (``plant = "artifact"``, alias ``linear``: the
    #: artifact's discrete plant about its one operating point).
    own_plant: str = "artifact"

    def refuse(self, cell: str, *, what: str | None = None) -> None:
        """The law's (:meth:`gainlink.laws.base.Law.refuse`)."""
        raise NotImplementedError

    def sigma_of(self, artifact: Any, y: np.ndarray, s: np.ndarray) -> float:
        """The scheduling variable the sample ``y``, ``s`` gives, clipped into the law's envelope (where a run
        starts); NaN for a law without one."""
        return math.nan

    def integrator_columns(self, artifact: Any) -> slice | None:
        """Where the integrators lie in a row of ``Controller.state()`` of this law's float64 reference (the
        columns :meth:`integrators` reads; a campaign block's twin records only these); None for a law that keeps
        none."""
        return None

    def integrators(self, artifact: Any, states: np.ndarray) -> np.ndarray | None:
        """The integrators (N, q) in rows of ``Controller.state()`` of this law's float64 reference (N, ...); None
        for a law that keeps none (:meth:`integrator_columns`)."""
        columns = self.integrator_columns(artifact)
        return None if columns is None else np.asarray(states)[:, columns]

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        """The design's own model of the plant, started at the plant's ``state`` by name (absolute, or a deviation
        from the operating point when ``deviation``; None: unknown) and ``sigma``, as a plant: ``outputs()``,
        ``advance(u)`` and, when it follows its law's sigma, ``follow(sigma)``. Returns ``(model, note)``, the note
        saying where it started; ``(None, why)`` when the artifact gives no such model."""
        return None, "off: this law has no design model"

    def shadow(self, artifact: Any, *, like: str) -> Any:
        """What a loop steps beside a link whose commands do not carry everything this law's step reports (a
        scheduled law's sigma): the peer's law in this process, fed what the peer received (``like`` the peer:
        ``reference``, the float64 law; else the bit-exact model of the C). None when the commands carry it all."""
        return None

    def native_block(self, artifact: Any, count: int, *, library: Any = None) -> Any:
        """``count`` instances of the law's host C stepped by one call per step (a campaign block:
        :class:`gainlink.laws.block.NativeBlock`); row i answers as instance i's own ``native`` step would."""
        from .block import NativeBlock

        return NativeBlock(artifact, count, library=library)

    def reference_block(self, artifact: Any, count: int) -> Any:
        """``count`` instances of the law's float64 reference stepped together (the twins of a campaign block); by
        default one after the other (:class:`gainlink.laws.block.OneByOne`)."""
        from .block import OneByOne

        return OneByOne([self.reference(artifact) for _ in range(count)])

    def describe(self, artifact: Any) -> dict:
        """What a run's report says about the artifact beyond its identity (the compensator, a schedule, units)."""
        return {"units": dict(artifact.signals["units"])} if artifact.signals.get("units") else {}

    def without_rate_limit(self, artifact: Any) -> Any:
        """A copy of ``artifact`` whose law does not limit its scheduling variable's rate (a probe, never a way to
        fly); :class:`LawError` for a law without one."""
        raise LawError(f"sigma_rate_limit = false is for a scheduled law; the {self.label} law has no sigma")

    def run_report(self, artifact: Any, trace: Any, *, ran: str | None, design_model: bool) -> dict:
        """The law's own blocks of a closed-loop run's metrics, from its trace (``gainlink.hil.loop.metrics
        .RunTrace``, twins included): ``ran`` is the label of the law the controller says it ran (None: the float64
        reference ran), ``design_model`` whether the plant is the design's own model."""
        return {}

    def simulate(self, artifact: Any, *, steps: int, x0: Any = None, reference: Any = None, noise_std: float = 0.0,
                 seed: int = 0, signals: Any = None) -> Any:  # fmt: skip
        """A closed-loop run of the law's float64 reference around the artifact's own discrete plant
        (:class:`gainlink.proof.simulation.Simulation`); ``x0`` is a deviation from the operating point, ``signals``
        the external scheduling signals ((e,) or (steps, e)) of a law that has them."""
        self.refuse("simulate")
        raise LawError(f"simulate is not available for the {self.label} law")

    def report_lines(self, metrics: Mapping[str, Any]) -> list[str]:
        """The run summary's lines on this law's own blocks of ``metrics`` (:meth:`run_report`)."""
        return []

    def image_stream(self, artifact: Any, *, target: str, board: str) -> Any:
        """The law's replay-only Cortex-M image for ``target`` on ``board`` (built and cached) and how a loop talks
        to it over its semihosting FIFOs (:class:`~gainlink.laws.image.ImageStream`: processor in the loop)."""
        self.refuse("pil")
        raise LawError(f"pil is not available for the {self.label} law")

    def pil_check(self, artifact: Any, records: np.ndarray, *, Y: np.ndarray, R: np.ndarray, S: np.ndarray,
                  trace: Any, twin_u: np.ndarray | None, design_model: bool, check_plant: Any) -> dict:  # fmt: skip
        """The law's own blocks of a PIL run: the image's output ``records`` checked against the law's oracles on
        the samples it was sent (``Y``, ``R``, ``S`` in float64: the image got them in float32); ``trace`` holds the
        run's flags and sigma, ``twin_u`` the float64 twin's commands, ``check_plant`` a further instance of the
        plant in the run's initial state for a check that closes a loop of its own (None: none)."""
        return {}

    def pil_lines(self, summary: Mapping[str, Any]) -> list[str]:
        """The PIL summary's lines on this law's own blocks of ``summary`` (:meth:`pil_check`, as JSON)."""
        return []

    def cost(self, artifact: Any, *, target: str, board: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray) -> Any:
        """Instructions per step of the law's C on ``target``'s image, callees included, replaying the samples
        (``gainlink.firmware.cost.StepCost``: mean, cheapest, dearest)."""
        self.refuse("cost")
        raise LawError(f"cost is not available for the {self.label} law")

    def cost_bound(self, artifact: Any, elf: Any, *, target: str, board: str) -> dict | None:
        """The proved bound on the instructions of the law's step in the image ``elf`` (``target`` on ``board``), as
        ``pil.json``'s ``instructions_per_step.bound``: per iteration and per step at the cap, whether it is proved,
        what it covers and its premises; None for a law that states none."""
        return None
