"""The certificate's closed-loop rounding bound when the law's samples and references cross a float32 link
(docs/design.md, fixed point: PIL).

The fixed-point C takes its samples and references as floats and returns its commands as floats
(``gl_fixed_step``), and the certificate is about the integer law between those floats: its rounding budget
holds the quantisation of a float sample to the sample's format (half a unit of ``f_y``, ``f_r``), the command
word's rounding (half a unit of ``f_u``) and the float the C returns (``(float)U``: exact in q15, within half a
float32 unit of the largest command word in q31). Where the samples are float32 roundings of finer values (PIL:
the plant is simulated in float64 and its samples travel as float32, while the float64 twin samples its plant
exactly), each sample and reference carries one more error, at most half a float32 ulp of the largest magnitude
in its declared range; in q31 that is far more than half a unit of the formats (a float32 has 24 significant
bits). The commands need nothing more: the float the C returns is what drives the plant.
:func:`bound_float32_link` is the certificate's closed-loop bound (:func:`~.error.closed_loop_bound`: the
same quantised coefficients, design model and WCPG) with those errors added.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...shipping.artifact import Artifact
from .error import closed_loop_bound
from .formats import rounding
from .model import gains_from_artifact


def float32_half_ulp(lo, hi) -> np.ndarray:
    """An upper bound of ``|float32(x) - x|`` over ``lo <= x <= hi`` (elementwise: half the float32 spacing at the
    larger magnitude)."""
    top = np.maximum(np.abs(np.asarray(lo, dtype=np.float64)), np.abs(np.asarray(hi, dtype=np.float64)))
    return np.spacing(top.astype(np.float32)).astype(np.float64) / 2.0


def bound_float32_link(a: Artifact) -> np.ndarray:
    """Per input, the bound of ``|u - u_q|`` (``u``: the float32 command of the integer law fed float32 samples
    and references; ``u_q``: the float64 law with the same quantised coefficients, sampling exactly) in closed loop
    around the design model while no input saturates and no sample is clipped (module docstring)."""
    ranges = a.checks["fixed_point"]["ranges"]
    g = gains_from_artifact(a)
    h = rounding(g)
    link = replace(
        h,
        y=h.y + float32_half_ulp(ranges["y_min"], ranges["y_max"]),
        r=h.r + (float32_half_ulp(ranges["r_min"], ranges["r_max"]) if a.q else 0.0),
    )
    return closed_loop_bound(g.ideal, (a.Ad, a.Bd, a.Cd, a.Dd), link)
