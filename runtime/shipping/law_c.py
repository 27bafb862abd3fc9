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
from typing import Any


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
