"""The lq structure in q31/q15 (the fixed-point pairs ``lq/q31``, ``lq/q15``): everything that is this family's
(docs/design.md, "Adding a law").

- the law (:mod:`.law`) and its design step (:mod:`.design`: the certificate as the implementation check);
- the certificate: formats (:mod:`.formats`), range bounds (:mod:`.ranges`), the command's error (:mod:`.error`,
  over the linear systems of :mod:`.loops`), the verdict (:mod:`.certificate`), a float32 link's bound
  (:mod:`.link`);
- the integers: binary formats and operations (:mod:`.qformat`), the quantised gains (:mod:`.gains`), the
  bit-exact model of the C (:mod:`.model`), its one-step check (:mod:`.onestep`), the closed-loop fidelity
  (:mod:`.fidelity`);
- the C: its export and MAVLink parameter table (:mod:`.codegen`), its host build and images (:mod:`.firmware`),
  as replay engines (:mod:`.engines`) and a ctypes controller (:mod:`.native`);
- the loops: the closed-loop run check (:mod:`.run`), processor in the loop and cost (:mod:`.pil`).
"""

from ...shipping import codegen as lq_codegen
from ...shipping import export_c, params
from . import codegen
from .law import FixedLaw

# the lq/q31 and lq/q15 laws' parts the layers below read (gainlink.registry): their C files and parameter tables
for _law in codegen.INTEGER_LAWS:
    export_c.RENDERINGS.register(_law, (codegen.render_export, lq_codegen.SOURCE_NAME))
    params.TABLES.register(_law, codegen.param_table)

__all__ = ["FixedLaw"]
