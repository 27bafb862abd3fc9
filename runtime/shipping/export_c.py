"""The C export of an artifact: every file ``gainlink export`` writes and the firmware is built from.

The law's own files (:func:`gainlink.shipping.codegen.render_c` for the lq structure, with a fixed-point law's
integers; :func:`gainlink.shipping.codegen_scheduled.render_scheduled` for the scheduled one), and what
``firmware/include/gainlink/gl_law.h`` and the nodes read for every law: ``gl_flags.h`` (the one flag table,
:mod:`gainlink.shipping.flags`), ``gl_record_<law>.h`` (the record of each law the export builds,
:mod:`gainlink.shipping.records`) and ``gl_law_params.h`` (the law's MAVLink parameter table,
:mod:`gainlink.shipping.params`). The same artifact always
gives the same bytes.
"""

from __future__ import annotations

from . import codegen, codegen_mpc, codegen_scheduled, params, records
from .artifact import Artifact
from .flags import c_header as flags_header
from .law_c import buildable, law_pair


def render_export(artifact: Artifact) -> dict[str, str]:
    """The C files of ``artifact``'s export, by name (module docstring)."""
    structure = law_pair(artifact)[0]
    render, source = {
        "scheduled": (codegen_scheduled.render_scheduled, codegen_scheduled.SOURCE_NAME),
        "mpc": (codegen_mpc.render_mpc, codegen_mpc.SOURCE_NAME),
    }.get(structure, (codegen.render_c, codegen.SOURCE_NAME))
    files = render(artifact)
    # the headers hold the artifact's structure only and name the source that holds the rest
    banner = codegen.structure_banner(source)
    files["gl_flags.h"] = flags_header()
    for law in buildable(artifact):
        files[records.header_name(law)] = records.c_header(artifact, law=law, banner=banner)
    files["gl_law_params.h"] = params.c_header(artifact, banner=banner)
    return files
