"""The C export of an artifact: every file ``gainlink export`` writes and the firmware is built from.

The law's own files (:data:`RENDERINGS`: :func:`gainlink.shipping.codegen.render_c` for the lq structure, with a
fixed-point law's integers from :mod:`.codegen_fixed`; :func:`gainlink.shipping.codegen_scheduled.render_scheduled`
for the scheduled one), and what
``firmware/include/gainlink/gl_law.h`` and the nodes read for every law: ``gl_flags.h`` (the one flag table,
:mod:`gainlink.shipping.flags`), ``gl_record_<law>.h`` (the record of each law the export builds,
:mod:`gainlink.shipping.records`) and ``gl_law_params.h`` (the law's MAVLink parameter table,
:mod:`gainlink.shipping.params`). The same artifact always
gives the same bytes.
"""

from __future__ import annotations

from collections.abc import Callable

from . import codegen, codegen_fixed, codegen_mpc, codegen_scheduled, params, records
from .artifact import Artifact
from .flags import c_header as flags_header
from .law_c import buildable, law_name


def _lq_integers(artifact: Artifact) -> dict[str, str]:
    """The lq structure's files, whose signature covers the integers' formats and terms, and the integers."""
    files = codegen.render_c(artifact, more=codegen_fixed.described(artifact))
    return files | codegen_fixed.render_fixed(artifact)


#: Each law's own files (its C rendering) and the source its headers name: the registry the export asks.
RENDERINGS: dict[str, tuple[Callable[[Artifact], dict[str, str]], str]] = {
    "lq/float32": (codegen.render_c, codegen.SOURCE_NAME),
    "lq/q31": (_lq_integers, codegen.SOURCE_NAME),
    "lq/q15": (_lq_integers, codegen.SOURCE_NAME),
    "scheduled/float32": (codegen_scheduled.render_scheduled, codegen_scheduled.SOURCE_NAME),
    "mpc/float32": (codegen_mpc.render_mpc, codegen_mpc.SOURCE_NAME),
}


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
