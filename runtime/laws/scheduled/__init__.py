"""The scheduled structure (the pair ``scheduled/float32``, the velocity-form law interpolated in sigma): everything
that is this family's (docs/design.md, "Adding a law").

- the law (:mod:`.law`) and its design: the points and the schedule (:mod:`.design`, over :mod:`.grid`), the
  verdict on sigma's variation (:mod:`.variation`: the LPV loop of :mod:`.lpv`, its hull :mod:`.hull`, the Lyapunov
  certificates of :mod:`.lyapunov` searched by :mod:`.certify`, the rate falsifier :mod:`.rate` over the sweeps of
  :mod:`.sweeps`), the design-time float32 fidelity (:mod:`.fidelity`);
- the float64 law (:mod:`.reference`), the bit-exact model of its C (:mod:`.model`), its one-step check with a
  float32 bound (:mod:`.onestep`), replay files (:mod:`.replay`);
- the C through ctypes (:mod:`.native`) and under QEMU (:mod:`.qemu`);
- the loops: the design's own plant model (:mod:`.plant`), the closed-loop run blocks (:mod:`.run`), processor in
  the loop and cost (:mod:`.pil`).
"""

from .law import ScheduledLaw

__all__ = ["ScheduledLaw"]
