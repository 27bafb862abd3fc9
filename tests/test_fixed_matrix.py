"""The exhaustive fixed-point matrix (`make test-matrix`, not `make test`): every example in q31 (and wood_berry in
q15, where its certificate allows) on every Cortex-M board, the image under QEMU equal to the host build bit for
bit (command words, unsaturated commands, estimate, integrators, flags, float commands)."""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.firmware.fixed import run_host, run_qemu
from gainlink.firmware.targets import BOARDS
from support.fixed import example

pytestmark = pytest.mark.matrix

LAWS = [("pendulum", "q31"), ("quadrotor_lateral", "q31"), ("wood_berry", "q31"), ("wood_berry", "q15")]


@pytest.mark.parametrize("board", list(BOARDS))
@pytest.mark.parametrize("name,numeric", LAWS, ids=[f"{n}-{q}" for n, q in LAWS])
def test_fixed_point_image_equals_the_host(name, numeric, board):
    a = example(name, numeric)
    ranges = a.checks["fixed_point"]["ranges"]
    rng = np.random.default_rng(11)
    lo, hi = np.array(ranges["y_min"]), np.array(ranges["y_max"])
    Y = (lo + (hi - lo) * rng.uniform(-0.1, 1.1, (300, a.p))).astype(np.float32)
    rlo, rhi = np.array(ranges["r_min"]), np.array(ranges["r_max"])
    R = (rlo + (rhi - rlo) * rng.uniform(-0.1, 1.1, (300, a.q))).astype(np.float32)
    host, image = run_host(a, Y, R), run_qemu(a, Y, R, board=board, target=BOARDS[board].core)
    for field in ("U", "V", "XH", "Z", "flags", "sat", "clip", "overflow"):
        assert np.array_equal(getattr(host, field), getattr(image, field)), field
    assert np.array_equal(host.u.view(np.uint32), image.u.view(np.uint32))
