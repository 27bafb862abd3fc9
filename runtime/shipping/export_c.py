"""The C export of an artifact: every file ``gainlink export`` writes and the firmware is built from.

The law's own files (:data:`RENDERINGS`, each family's: :func:`gainlink.shipping.codegen.render_c` for the lq
structure in float32, the families' own renderings for the others), and what
``firmware/include/gainlink/gl_law.h`` and the nodes read for every law: ``gl_flags.h`` (the one flag table,
:mod:`gainlink.shipping.flags`), ``gl_record_<law>.h`` (the record of each law the export builds,
:mod:`gainlink.shipping.records`) and ``gl_law_params.h`` (the law's MAVLink parameter table,
:mod:`gainlink.shipping.params`). The same artifact always
gives the same bytes.
"""

from __future__ import annotations

from collections.abc import Callable

from ..registry import LawTable
from . import codegen, params, records
from .artifact import Artifact
from .flags import c_header as flags_header
from .law_c import buildable, law_name

#: Each law's own files (its C rendering, ``artifact -> {name: text}``) and the source its headers name: the table
#: the export asks, registered by the law families (:mod:`gainlink.registry`).
RENDERINGS: LawTable[tuple[Callable[[Artifact], dict[str, str]], str]] = LawTable("C rendering")


def render_export(artifact: Artifact) -> dict[str, str]:
    """The C files of ``artifact``'s export, by name (module docstring)."""
    render, source = RENDERINGS[law_name(artifact)]
    files = render(artifact)
    # the headers hold the artifact's structure only and name the source that holds the rest
    banner = codegen.structure_banner(source)
    files["gl_flags.h"] = flags_header()
    for law in buildable(artifact):
        files[records.header_name(law)] = records.c_header(artifact, law=law, banner=banner)
    files["gl_law_params.h"] = params.c_header(artifact, banner=banner)
    return files
