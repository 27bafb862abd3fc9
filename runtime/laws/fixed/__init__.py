"""The lq structure in q31/q15 (the fixed-point pairs ``lq/q31``, ``lq/q15``): everything that is this family's
(docs/design.md, "Adding a law"): the law (:mod:`.law`), its closed-loop run check (:mod:`.run`) and its
processor-in-the-loop check and cost (:mod:`.pil`)."""

from .law import FixedLaw

__all__ = ["FixedLaw"]
