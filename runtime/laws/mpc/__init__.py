"""The MPC law (docs/design.md, "MPC (the fourth law)"): linear MPC on the observer-based law's estimate and
integrators, solved by ADMM whose primal step is a Riccati backward/forward pass on per-stage gains cached at design
time. :mod:`.block` (the artifact's ``mpc`` block, which the artifact loader reads through its table), :mod:`.spec` (the
spec's ``[mpc]`` table), :mod:`.design` (making it), :mod:`.codegen` (its C and MAVLink parameter table), :mod:`.qp`
(the QP solved to optimality: Clarabel, a KKT solve), :mod:`.arith` (float64 and the C's float32), :mod:`.solver` (the
ADMM), :mod:`.step` (one step of the law), :mod:`.law` (:class:`MpcLaw`).
"""

from ...shipping import artifact, export_c, params, systems
from ...spec import parse
from . import block, codegen, spec
from .law import MpcLaw

# the mpc/float32 law's parts the layers below read (gainlink.registry): the artifact's mpc block, its C files and
# parameter table, the spec's [mpc] table and implementation check; its frozen-point coefficients, plant and operating
# point are the lq structure's (with no box active its optimum is the lq law of the same weights)
artifact.BLOCKS.register("mpc", block.load_mpc)
export_c.RENDERINGS.register("mpc/float32", (codegen.render_mpc, codegen.SOURCE_NAME))
params.TABLES.register("mpc/float32", codegen.param_table)
systems.COEFFICIENTS.register("mpc", systems.lq_coefficients)
parse.PLANTS.register("mpc", parse.lq_plants)
parse.OPERATING.register("mpc", parse.lq_operating)
parse.CHECKS.register("mpc", spec.check_implementation)
parse.BLOCKS.register("mpc", spec.parse_mpc)

__all__ = ["MpcLaw"]
