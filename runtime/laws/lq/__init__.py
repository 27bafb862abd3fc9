"""The lq structure in float32 (the pair ``lq/float32``, the observer-based law of docs/design.md §2): everything
that is this family's (docs/design.md, "Adding a law"): the law (:mod:`.law`) and its design step's float32 check
(:mod:`.design`), the bit-exact model of its C (:mod:`.model`, its step compiled by :mod:`.step`), the float32
closed-loop fidelity (:mod:`.fidelity`, which the fixed-point and scheduled checks run too), its golden vectors
(:mod:`.golden`) and its closed-loop, PIL and cost hooks (:mod:`.run`)."""

from .law import LqLaw

__all__ = ["LqLaw"]
