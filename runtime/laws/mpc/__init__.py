"""The MPC law (docs/design.md, "MPC (the fourth law)"): linear MPC on the observer-based law's estimate and
integrators, solved by ADMM whose primal step is a Riccati backward/forward pass on per-stage gains cached at design
time. :mod:`.design` (the ``mpc`` block), :mod:`.qp` (the QP solved to optimality: Clarabel, a KKT solve),
:mod:`.arith` (float64 and the C's float32), :mod:`.solver` (the ADMM), :mod:`.step` (one step of the law),
:mod:`.law` (:class:`MpcLaw`)."""

from .law import MpcLaw

__all__ = ["MpcLaw"]
