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
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

from ..errors import DataError, GainlinkError, LawError, did_you_mean
from ..shipping.law_c import CANNOT, CELLS, refusal
from .hooks import LoopHooks

if TYPE_CHECKING:
    from ..proof.sampled_plant import SampledPlant
    from ..spec import PlantSpec
    from ..synthesis.pipeline import DesignResult

#: The replay engines of every law: its float64 law, the bit-exact model of its C, the host build of the C through
#: ctypes, and a Cortex-M image under QEMU (``target`` and ``board`` choose which).
ENGINES: tuple[str, ...] = ("reference", "model", "native", "qemu")


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
class OneStepVerdict:
    """A one-step (resynchronised) check of a trace, and what the trace was checked against.

    ``check`` has ``passed``, ``summary()`` and ``first_failure.describe(name)``
    (:class:`~gainlink.proof.onestep.OneStepCheck` or :class:`~gainlink.laws.fixed.onestep.FixedOneStepCheck`).
    """

    against: str
    check: Any

    @property
    def passed(self) -> bool:
        """Whether every step held."""
        return bool(self.check.passed)


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
        """What this pair can do: its declaration (:data:`gainlink.shipping.law_c.CANNOT`)."""
        return Capabilities(cannot=CANNOT[self.name])

    def refuse(self, cell: str, *, what: str | None = None) -> None:
        """Raise :class:`LawError` (one line) unless the pair can do ``cell``; ``what`` names the request."""
        if cell not in CELLS:
            raise ValueError(f"unknown cell {cell!r}")
        reason = self.capabilities.cannot.get(cell)
        if reason is not None:
            raise LawError(refusal(self.label, cell, reason, what=what))

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

    @abstractmethod
    def u_op(self, artifact: Any, *, sigma: float | None = None) -> np.ndarray:
        """The command that holds the plant at its operating point, unclamped (a scheduled law: at ``sigma``, by
        default its first point)."""

    def externals(self, artifact: Any) -> tuple[str, ...]:
        """The names of the external scheduling signals a sample carries after its references (none by default)."""
        return ()

    # -- the design side: design, replay, the one-step check, the trace files, the C rendering ------------------

    @abstractmethod
    def design(self, spec: PlantSpec) -> DesignResult:
        """Design the law ``spec`` asks for: the sealed artifact and the numbers behind its checks."""

    @abstractmethod
    def plant(self, artifact: Any, *, sigma: float | None = None) -> SampledPlant:
        """The design's own sampled plant about its trim (a scheduled law's: frozen at ``sigma``)."""

    def replay(
        self,
        artifact: Any,
        engine: str,
        Y: np.ndarray,
        R: np.ndarray,
        S: np.ndarray | None = None,
        *,
        target: str | None = None,
        board: str | None = None,
    ) -> Any:
        """``Y`` (N, p), ``R`` (N, q) and the external signals ``S`` (N, e) through ``engine`` (:data:`ENGINES`)
        from the law's start; ``target`` and ``board`` choose the Cortex-M image of ``qemu``.

        Raises
        ------
        GainlinkError
            An unknown engine, a target or board for another engine than ``qemu``, an unknown target or board.
        DataError
            The law is scheduled on external signals and ``S`` is missing.
        """
        if engine not in ENGINES:
            known = ", ".join(ENGINES)
            raise GainlinkError(f"unknown engine {engine!r}{did_you_mean(engine, ENGINES)} (engines: {known})")
        externals = self.externals(artifact)
        if externals and S is None:
            raise DataError(
                f"the {self.label} law of artifact {artifact.name} reads {len(externals)} external signal(s) "
                f"({', '.join(externals)}) beside its samples: give s (N, {len(externals)})"
            )
        S = np.asarray(S, dtype=float).reshape(len(Y), len(externals)) if externals else None
        platform = None
        if engine == "qemu":
            from ..firmware.targets import resolve_cortex_m

            platform = resolve_cortex_m(target, board)
        elif target is not None or board is not None:
            raise GainlinkError(f"--target and --board choose the image of --engine qemu, not of {engine}")
        return self._replay(artifact, engine, Y, R, S, platform=platform)

    @abstractmethod
    def _replay(self, artifact: Any, engine: str, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, *,
                platform: Any) -> Any:  # fmt: skip
        """:meth:`replay` once the engine and image are checked (``platform``: the resolved Cortex-M image)."""

    @abstractmethod
    def one_step(
        self, artifact: Any, Y: np.ndarray, R: np.ndarray, S: np.ndarray | None, trace: Any, *, engine: str | None
    ) -> tuple[OneStepVerdict, ...]:
        """Check every step of ``trace`` (what ``engine`` returned for these samples; ``None``: a trace file of this
        law's format from any engine) from the trace's own state, each against what proves it."""

    @abstractmethod
    def trace_text(self, artifact: Any, trace: Any, t: np.ndarray | None = None, *, engine: str | None = None) -> str:
        """The replay output CSV of ``trace`` (what ``engine`` returned), as ``gainlink replay`` writes it."""

    @abstractmethod
    def read_trace(self, path: str | Path, artifact: Any) -> Any:
        """A replay output CSV of this law back into a trace (:class:`~gainlink.errors.DataError` when it is not
        one of this artifact, or names another numeric format)."""

    @abstractmethod
    def records_trace(self, artifact: Any, records: np.ndarray) -> Any:
        """The trace of the law's C records (:func:`gainlink.shipping.records.layout`: what the host executable
        ``gainlink_loop_host`` and the image write), the trace ``replay --engine native`` gives for the same
        samples."""

    def host_run_note(self, artifact: Any, records: np.ndarray, trace: Any) -> str:
        """What ``firmware run --input`` prints after the executable's name, of a replay through it: its ``records``
        (:meth:`records_trace`'s input) and ``trace`` counted (saturated and refused steps)."""
        saturated, refused = int(trace.saturated.any(axis=1).sum()), int(trace.fault.sum())
        return f": {saturated} saturated, {refused} refused"

    def export(self, artifact: Any) -> dict[str, str]:
        """The C files of the law's export (``gainlink export``), by name; the same artifact, the same bytes: its
        gains, its record and parameter table, the flags, rendered from the law's descriptions
        (:func:`gainlink.shipping.export_c.render_export`; the C chooses the law from the header at compile time)."""
        from ..shipping.export_c import render_export

        return render_export(artifact)

    # -- what the commands print about a law --------------------------------------------------------------------

    @abstractmethod
    def design_lines(self, result: DesignResult, path: Path) -> list[str]:
        """What ``gainlink design`` prints of ``result``, written to ``path``."""

    @abstractmethod
    def design_json(self, result: DesignResult, path: Path) -> dict:
        """``gainlink design --json``."""

    @abstractmethod
    def design_plots(self, artifact: Any) -> tuple[dict[str, bytes], str | None]:
        """``design --plots``: PNG files by name, and why nothing was drawn (None: drawn)."""

    @abstractmethod
    def open_loop_note(self, artifact: Any) -> str:
        """What ``replay --compare`` says of two replays compared open loop (the compensator's stability)."""

    def analysis_lines(self, report: Any) -> list[str]:
        """What ``gainlink analyze`` adds for this law after the checks of the spec's design (nothing by default)."""
        return []

    def __repr__(self) -> str:
        return f"<law {self.name}>"
