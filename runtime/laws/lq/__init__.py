"""The lq structure in float32 (the pair ``lq/float32``, the observer-based law of docs/design.md §2): everything
that is this family's (docs/design.md, "Adding a law"): the law (:mod:`.law`) and its closed-loop, PIL and cost
hooks (:mod:`.run`)."""

from .law import LqLaw

__all__ = ["LqLaw"]
