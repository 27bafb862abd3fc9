"""The scheduled structure (the pair ``scheduled/float32``, the velocity-form law interpolated in sigma): everything
that is this family's (docs/design.md, "Adding a law"): the law (:mod:`.law`), its design-time float32 fidelity
(:mod:`.fidelity`), its one-step check with a float32 bound (:mod:`.onestep`), the design's own plant model
(:mod:`.plant`), its closed-loop run blocks (:mod:`.run`), processor in the loop and cost (:mod:`.pil`)."""

from .law import ScheduledLaw

__all__ = ["ScheduledLaw"]
