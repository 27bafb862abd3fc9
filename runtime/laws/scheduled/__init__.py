"""The scheduled structure (the pair ``scheduled/float32``, the velocity-form law interpolated in sigma): everything
that is this family's (docs/design.md, "Adding a law").

- the law (:mod:`.law`), the spec's ``[schedule]`` (:mod:`.spec`), the artifact's ``schedule`` block (:mod:`.block`) and
  its design: the points and the schedule (:mod:`.design`, over :mod:`.grid`), the verdict on sigma's variation
  (:mod:`.variation`: the LPV loop of :mod:`.lpv`, its hull :mod:`.hull`, the Lyapunov certificates of :mod:`.lyapunov`
  searched by :mod:`.certify`, the rate falsifier :mod:`.rate` over the sweeps of :mod:`.sweeps`), the design-time
  float32 fidelity (:mod:`.fidelity`);
- the float64 law (:mod:`.reference`), the bit-exact model of its C (:mod:`.model`), its one-step check with a
  float32 bound (:mod:`.onestep`), replay files (:mod:`.replay`);
- its C and MAVLink parameter table (:mod:`.codegen`), the C through ctypes (:mod:`.native`) and under QEMU
  (:mod:`.qemu`);
- the loops: the design's own plant model (:mod:`.plant`), the closed-loop run blocks (:mod:`.run`), processor in
  the loop and cost (:mod:`.pil`).
"""

from ...shipping import artifact, export_c, params, systems
from ...spec import parse
from . import block, codegen, spec
from .law import ScheduledLaw

# the scheduled/float32 law's parts the layers below read (gainlink.registry): the artifact's schedule block, its C
# files and parameter table, its frozen-point coefficients, the spec's plants and operating points per point
artifact.BLOCKS.register("schedule", block.load_schedule)
export_c.RENDERINGS.register("scheduled/float32", (codegen.render_scheduled, codegen.SOURCE_NAME))
params.TABLES.register("scheduled/float32", codegen.param_table)
systems.COEFFICIENTS.register("scheduled", block.frozen_coefficients)
parse.PLANTS.register("scheduled", spec.scheduled_plants)
parse.OPERATING.register("scheduled", spec.scheduled_operating)

__all__ = ["ScheduledLaw"]
