"""Which law an artifact runs, as its C export names it: the one place that reads it from the artifact's content.

A law is a pair structure x numeric format (docs/design.md, "Adding a law"): a ``schedule`` block makes the
``scheduled`` structure, an ``mpc`` block the ``mpc`` structure, else ``lq``; ``checks.fixed_point.numeric``
makes an integer format, else ``float32``.
:func:`law_name` decides it (``gainlink.laws.law_of`` asks it too); the export writes the pair into ``gl_gains.h``
(``GL_LAW_STRUCTURE``, ``GL_LAW_NUMERIC``), where ``firmware/include/gainlink/gl_law.h`` and the firmware's CMake
read which law to build, with the law's compatibility signature (``GL_LAW_SIGNATURE``), which a gain set must carry
for ``gl_law_stage`` to accept it.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from typing import Any

from ..errors import ArtifactError, LawError

#: Everything a consumer may ask of a law (issue 30's cells). A pair declares which it cannot do (:data:`CANNOT`);
#: asking for one of those is one line (:func:`refusal`). ``gainlink.laws`` reads the same table.
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

#: Each pair's declaration of the cells it cannot do yet, with the reason (the one declaration: the laws'
#: ``Capabilities`` are these, and the layers below the laws refuse from them with :func:`refuse`).
CANNOT: dict[str, dict[str, str]] = {
    "lq/float32": {},
    "lq/q31": {
        "fuzz": "the fuzz harnesses are built on the float32 lq law's gain set (firmware/fuzz/fuzz_gains_stage.c "
        "stages a gl_gains_t through gl_loop_stage, which a fixed-point export does not link)",
    },
    "scheduled/float32": {
        "fuzz": "the fuzz harnesses are built on the float32 lq law's gain set (firmware/fuzz/fuzz_gains_stage.c "
        "stages a gl_gains_t, and the seeds are its field table)",
    },
    "mpc/float32": {
        "fidelity": "its design records no float32 fidelity figure (a bound on the C against the float64 algorithm "
        "over any history is not derived for the ADMM); each step of a trace is checked instead: bit "
        "for bit its float32 model, within the solver's tolerance of the float64 algorithm (one_step)",
    },
}
CANNOT["lq/q15"] = CANNOT["lq/q31"]

#: Each structure in a few words, from its artifact (what a refusal of another structure's part says of it).
STRUCTURES: dict[str, Callable[[Any], str]] = {
    "lq": lambda a: "one positional law about one operating point",
    "scheduled": lambda a: f"the velocity-form law scheduled on {a.schedule.sigma}",
    "mpc": lambda a: f"the constrained MPC law over a horizon of {a.mpc.horizon} steps",
}


def refusal(label: str, cell: str, reason: str, *, what: str | None = None) -> str:
    """The one line that refuses ``cell`` (asked as ``what``) of the ``label`` law, for its declared ``reason``."""
    if cell not in CELLS:
        raise ValueError(f"unknown cell {cell!r}")
    return f"{what or cell} is not available for the {label} law: {reason}"


def refuse(artifact: Any, cell: str, *, what: str | None = None) -> None:
    """Raise :class:`LawError` (one line, :func:`refusal`) when the law ``artifact`` runs declares it cannot do
    ``cell`` (:data:`CANNOT`)."""
    reason = CANNOT[law_name(artifact)].get(cell)
    if reason is not None:
        raise LawError(refusal(law_label(artifact), cell, reason, what=what))


#: The structures whose artifact holds one positional law about one operating point (its trim, safe command and
#: design plant are the artifact's own; the scheduled law has one per point).
ONE_OPERATING_POINT: tuple[str, ...] = ("lq", "mpc")


def require_structure(artifact: Any, structure: str | tuple[str, ...], what: str) -> None:
    """Raise :class:`ArtifactError` (one line) when ``what``, a part of the ``structure`` law (its float64 law, its
    C gain set, its one operating point...), is asked of an artifact whose law has another structure: that law has
    its own (``gainlink.laws.law_of``). A tuple names every structure that has it, the first named in the line."""
    allowed = (structure,) if isinstance(structure, str) else structure
    structure = allowed[0]
    own = law_pair(artifact)[0]
    if own not in allowed:
        raise ArtifactError(
            f"{what} is the {structure} law's ({STRUCTURES[structure](artifact)}); {artifact.name} runs the "
            f"{law_label(artifact)} law ({STRUCTURES[own](artifact)}), which has its own (gainlink.laws.law_of)"
        )


def require_law(artifact: Any, laws: tuple[str, ...], what: str) -> None:
    """Raise :class:`ArtifactError` (one line) when ``what``, a part of the laws ``laws`` only (``structure/numeric``:
    a fixed-point law's integers, the scheduled law's tables), is asked of an artifact whose law is another."""
    own = law_name(artifact)
    if own not in laws:
        names = ", ".join(LABELS[law] for law in laws)
        raise ArtifactError(f"{what} is the {names} law's; {artifact.name} runs the {LABELS[own]} law")


def externals(artifact: Any) -> tuple[str, ...]:
    """The external scheduling signals a sample of ``artifact``'s law carries after its references, in order (none
    for a law without them, or one whose sigma is read from an output)."""
    return tuple(artifact.schedule.external) if law_pair(artifact)[0] == "scheduled" else ()


def sigma_name(artifact: Any) -> str | None:
    """The scheduling variable of the law ``artifact`` runs (None: a law without one)."""
    return artifact.schedule.sigma if law_pair(artifact)[0] == "scheduled" else None


def law_pair(artifact: Any) -> tuple[str, str]:
    """``(structure, numeric)`` of the law ``artifact`` runs."""
    data = artifact.data
    structure = "scheduled" if data.get("schedule") is not None else "mpc" if data.get("mpc") is not None else "lq"
    fixed = data.get("checks", {}).get("fixed_point")
    return structure, "float32" if fixed is None else str(fixed["numeric"])


def law_name(artifact: Any) -> str:
    """``structure/numeric`` of the law ``artifact`` runs (``lq/float32``, ``lq/q31``, ``scheduled/float32``)."""
    return "/".join(law_pair(artifact))


def buildable(artifact: Any) -> tuple[str, ...]:
    """The laws ``artifact``'s export can build: its own, and for an integer law the float32 loop of the same design
    (its export holds both: the benchmarks' baseline, ``GL_LAW=lq_float32``)."""
    own = law_name(artifact)
    return (own, "lq/float32") if own in ("lq/q31", "lq/q15") else (own,)


#: Each law's id (the HEARTBEAT's custom_mode and the image's output header: GL_LAW_ID of gl_law.h), the name ready
#: lines give it (GL_LAW_NAME) and its own step function (GL_LAW_STEP_SYMBOL: what an instruction count covers).
IDS = {"lq/float32": 0, "lq/q31": 31, "lq/q15": 15, "scheduled/float32": 256, "mpc/float32": 512}
LABELS = {"lq/float32": "float32", "lq/q31": "q31", "lq/q15": "q15", "scheduled/float32": "scheduled-float32",
          "mpc/float32": "mpc-float32"}  # fmt: skip
STEP_SYMBOLS = {"lq/float32": "gl_loop_step", "lq/q31": "gl_fixed_step", "lq/q15": "gl_fixed_step",
                "scheduled/float32": "gl_sched_step", "mpc/float32": "gl_mpc_step"}  # fmt: skip


#: Why a pair's gain set cannot be written through a ``--mapping`` onto another autopilot's parameters (a mapping
#: names one gain set); the pairs not here can.
NO_MAPPING = {"scheduled/float32": "a --mapping names one gain set, not its points"}


def mapping_refusal(artifact: Any) -> str | None:
    """Why ``artifact``'s gains cannot go through a ``--mapping`` (None: they can; :data:`NO_MAPPING`)."""
    return NO_MAPPING.get(law_name(artifact))


def label_of_id(law_id: int) -> str:
    """The label of the law whose GL_LAW_ID is ``law_id`` (a HEARTBEAT's custom_mode; ``"law 7"`` when it is none
    of :data:`IDS`)."""
    return next((LABELS[law] for law, i in IDS.items() if i == law_id), f"law {law_id}")


def law_label(artifact: Any) -> str:
    """What ready lines, banners and manifests name the law ``artifact`` runs by (GL_LAW_NAME of gl_law.h)."""
    return LABELS[law_name(artifact)]


def law_ids(artifact: Any, *, law: str | None = None) -> int:
    """GL_LAW_ID of ``law`` (default: the one ``artifact`` runs)."""
    return IDS[law or law_name(artifact)]


def step_symbol(artifact: Any, *, law: str | None = None) -> str:
    """The step function of ``law`` (default: ``artifact``'s) in a firmware image: what an instruction count covers
    (the law's own step, callees included; gl_law.h's wrapper around it only copies words and sets flags)."""
    return STEP_SYMBOLS[law or law_name(artifact)]


def c_name(law: str) -> str:
    """A law's name as C and CMake spell it (``lq/q31`` -> ``lq_q31``)."""
    return law.replace("/", "_")


def signature(text: str) -> int:
    """The compatibility signature of a law described by ``text`` (CRC-32 of it): what a gain set made for one build
    carries, and what another build's ``gl_law_stage`` compares with its own."""
    return zlib.crc32(text.encode("ascii"))


def macros(artifact: Any, *, described: str) -> str:
    """The lines of ``gl_gains.h`` that name the law: its pair and its signature over ``described`` (the dimensions
    and whatever else the compiled step depends on: number formats, the scheduled step's constant coefficients)."""
    structure, numeric = law_pair(artifact)
    sig = signature(f"{structure}/{numeric};{described}")
    return (
        f"#define GL_LAW_STRUCTURE {structure} /* the law this export runs: {structure}/{numeric} (gl_law.h) */\n"
        f"#define GL_LAW_NUMERIC {numeric}\n"
        f"#define GL_LAW_SIGNATURE 0x{sig:08x}u /* {structure}/{numeric};{described} */\n"
    )
