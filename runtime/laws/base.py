"""What a law is to everything that consumes one: a step result, a running controller, a declaration of what it
can do, and the law itself (docs/design.md, "Adding a law").

A law is a pair, structure (``lq``, ``scheduled``, ...) x numeric format (``float32``, ``q31``, ``q15``). Loops,
twins, replays and campaigns are written once against :class:`Controller` (``step(y, r, s) -> Step``); anything
that depends on the law asks the :class:`Law` (found by :func:`gainlink.laws.law_of`), never the artifact's shape.
The shapes imitate python-can's ``BusABC`` (required methods abstract, optional ones with a default, here a
refusal generated from the declaration) and python-control's ``input_output_response`` (a loop needs only a step).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

import numpy as np

from ..errors import LawError

#: Everything a consumer may ask of a law (issue 30's cells). A pair declares which it can do; the others carry a
#: reason, and asking for them is one line (:meth:`Law.refuse`).
CELLS: tuple[str, ...] = (
    "design",
    "codegen",
    "engine.native",
    "engine.qemu",
    "one_step",
    "replay",
    "twins",
    "simulate",
    "fidelity",
    "sil",
    "pil",
    "hil.can",
    "hil.mavlink",
    "fault.drop",
    "fault.delay",
    "fault.duplicate",
    "fault.reorder",
    "fault.nan",
    "fault.silent",
    "fault.crash",
    "realtime.host",
    "realtime.qemu",
    "upload.host",
    "upload.image",
    "slcan",
    "firmware_run",
    "fuzz",
    "campaign.sil",
    "campaign.hil",
    "cost",
)


@dataclass(frozen=True)
class Step:
    """What one step of any law returns, whoever ran it (the float64 law, the bit-exact model, the C, a node).

    Attributes
    ----------
    u : numpy.ndarray
        The command (m,), absolute; for the C and its models the float32 value the C returns, held in float64.
    flags : int
        Status flags (:mod:`gainlink.laws.flags`), the same bits on every link.
    sat : int
        Bit j set when input j was clamped to its limits.
    word : numpy.ndarray or None
        The native command words (m,) of an integer law (the fixed-point ``U``); None for a float law.
    sigma : float
        The scheduling variable the step used (scheduled laws); NaN for the others.
    """

    u: np.ndarray
    flags: int = 0
    sat: int = 0
    word: np.ndarray | None = None
    sigma: float = math.nan

    @property
    def saturated(self) -> np.ndarray:
        """Per input, whether it was clamped (from :attr:`sat`)."""
        return ((self.sat >> np.arange(self.u.size)) & 1).astype(bool)


class Controller(Protocol):
    """A running instance of a law.

    ``describe`` is what a report says about it (``{"kind": ..., ...}``). ``s`` holds the external scheduling
    signals (an empty array when the law has none).
    """

    describe: dict

    def step(self, y: np.ndarray, r: np.ndarray, s: np.ndarray) -> Step:
        """One sample: absolute outputs ``y`` (p), references ``r`` (q), external signals ``s`` (e)."""
        ...

    def reset(self) -> None:
        """Back to the law's start state."""
        ...

    def state(self) -> np.ndarray:
        """The law's state now, as one vector (its layout is the law's: :meth:`Law.integrators` reads it)."""
        ...


@dataclass(frozen=True)
class Capabilities:
    """What a pair can do: every cell of :data:`CELLS` either in ``can`` or refused with its reason in ``cannot``."""

    cannot: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        unknown = sorted(set(self.cannot) - set(CELLS))
        if unknown:
            raise ValueError(f"unknown cell(s) {', '.join(unknown)} (cells: {', '.join(CELLS)})")

    @property
    def can(self) -> tuple[str, ...]:
        """The cells the pair can do, in :data:`CELLS` order."""
        return tuple(c for c in CELLS if c not in self.cannot)


class Law(ABC):
    """One pair, structure x numeric format (module docstring).

    Subclasses (one per structure, in the structure's own module family) set :attr:`structure`, the numeric
    formats they run, and implement the required methods; the optional ones refuse by default.
    """

    structure: ClassVar[str]
    numerics: ClassVar[tuple[str, ...]]

    def __init__(self, numeric: str = "float32") -> None:
        if numeric not in self.numerics:
            raise LawError(f"the {self.structure} law has no {numeric} form (formats: {', '.join(self.numerics)})")
        self.numeric = numeric

    @property
    def name(self) -> str:
        """``structure/numeric``, e.g. ``lq/q31``."""
        return f"{self.structure}/{self.numeric}"

    @property
    @abstractmethod
    def label(self) -> str:
        """What ready lines and reports name the law by (``float32``, ``q31``, ``scheduled-float32``)."""

    @property
    def capabilities(self) -> Capabilities:
        """What this pair can do (default: every cell)."""
        return Capabilities()

    def refuse(self, cell: str, *, what: str | None = None) -> None:
        """Raise :class:`LawError` (one line) unless the pair can do ``cell``; ``what`` names the request."""
        if cell not in CELLS:
            raise ValueError(f"unknown cell {cell!r}")
        reason = self.capabilities.cannot.get(cell)
        if reason is not None:
            raise LawError(f"{what or cell} is not available for the {self.label} law: {reason}")

    # -- required: every consumer needs these -------------------------------------------------------------------

    @abstractmethod
    def reference(self, artifact: Any) -> Controller:
        """The float64 law of ``artifact``."""

    @abstractmethod
    def model(self, artifact: Any) -> Controller:
        """The bit-exact model of the C (float32 with explicit fma, or the integer law)."""

    @abstractmethod
    def native(self, artifact: Any, *, library: Any = None) -> Controller:
        """The host build of the C, through ctypes (built and cached by sha256 unless ``library`` is given)."""

    @abstractmethod
    def safe_command(self, artifact: Any) -> np.ndarray:
        """The command a refused sample gets before the law has run (its start)."""

    @abstractmethod
    def r_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        """The references that hold the plant at its operating point (a scheduled law: at ``sigma``)."""

    def externals(self, artifact: Any) -> tuple[str, ...]:
        """The names of the external scheduling signals a sample carries after its references (none by default)."""
        return ()

    # -- what a closed loop asks (gainlink.hil.loop); defaults for a law without a scheduling variable -------------

    def sigma_of(self, artifact: Any, y: np.ndarray, s: np.ndarray) -> float:
        """The scheduling variable the sample ``y``, ``s`` gives, clipped into the law's envelope (where a run
        starts); NaN for a law without one."""
        return math.nan

    def integrators(self, artifact: Any, states: np.ndarray) -> np.ndarray | None:
        """The integrators (N, q) in rows of :meth:`Controller.state` of this law's float64 reference (N, ...);
        None for a law that keeps none."""
        return None

    def design_model(self, artifact: Any, *, state: Mapping[str, float] | None, deviation: bool,
                     sigma: float) -> tuple[Any, str]:  # fmt: skip
        """The design's own model of the plant, started at the plant's ``state`` by name (absolute, or a deviation
        from the operating point when ``deviation``; None: unknown) and ``sigma``, as a plant: ``outputs()``,
        ``advance(u)`` and, when it follows its law's sigma, ``follow(sigma)``. Returns ``(model, note)``, the note
        saying where it started; ``(None, why)`` when the artifact gives no such model."""
        return None, "off: this law has no design model"

    def shadow(self, artifact: Any, *, like: str) -> Controller | None:
        """What a loop steps beside a link whose commands do not carry everything this law's step reports (a
        scheduled law's sigma): the peer's law in this process, fed what the peer received (``like`` the peer:
        ``reference``, the float64 law; else the bit-exact model of the C). None when the commands carry it all."""
        return None

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

    def __repr__(self) -> str:
        return f"<law {self.name}>"
