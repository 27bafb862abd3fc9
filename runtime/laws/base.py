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
from .hooks import LoopHooks

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


class Law(LoopHooks, ABC):
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

    def __repr__(self) -> str:
        return f"<law {self.name}>"
