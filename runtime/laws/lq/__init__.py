"""The lq structure in float32 (the pair ``lq/float32``, the observer-based law of docs/design.md §2): everything
that is this family's (docs/design.md, "Adding a law"): the law (:mod:`.law`) and its design step's float32 check
(:mod:`.design`), the bit-exact model of its C (:mod:`.model`, its step compiled by :mod:`.step`), the float32
closed-loop fidelity (:mod:`.fidelity`, which the fixed-point and scheduled checks run too), its golden vectors
(:mod:`.golden`) and its closed-loop, PIL and cost hooks (:mod:`.run`)."""

from ...shipping import codegen, export_c, params, systems
from ...spec import parse
from .law import LqLaw

# the lq/float32 law's parts the layers below read (gainlink.registry): its C files, parameter table, frozen-point
# coefficients and the spec's plant and operating point (the lq structure's, which the MPC structure shares)
export_c.RENDERINGS.register("lq/float32", (codegen.render_c, codegen.SOURCE_NAME))
params.TABLES.register("lq/float32", params.lq_table)
systems.COEFFICIENTS.register("lq", systems.lq_coefficients)
parse.PLANTS.register("lq", parse.lq_plants)
parse.OPERATING.register("lq", parse.lq_operating)

__all__ = ["LqLaw"]
