"""The exhaustive fixed-point matrix (`make test-matrix`, not `make test`): every example in q31 (and wood_berry in
q15, where its certificate allows) on every Cortex-M board, the image under QEMU equal to the host build bit for
bit (command words, unsaturated commands, estimate, integrators, flags, float commands), and run
processor-in-the-loop around the example's model: the image's records equal to the bit-exact model fed the very
samples it received, step for step, and its commands within the certified closed-loop bound (widened by the
link's float32 roundings) of the float64 law with the quantised coefficients (gainlink.laws.fixed.pil)."""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.firmware.targets import BOARDS
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.laws.fixed.firmware import run_host, run_qemu
from support.fixed import example

pytestmark = pytest.mark.matrix

LAWS = [("pendulum", "q31"), ("quadrotor_lateral", "q31"), ("wood_berry", "q31"), ("wood_berry", "q15")]
REFERENCES = {"pendulum": [0.5], "quadrotor_lateral": [1.0], "wood_berry": [1.0, -0.5]}  # within r_min..r_max
PIL_STEPS = 300


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


@pytest.mark.parametrize("board", list(BOARDS))
@pytest.mark.parametrize("name,numeric", LAWS, ids=[f"{n}-{q}" for n, q in LAWS])
def test_fixed_point_pil_on_every_board(name, numeric, board):
    a = example(name, numeric)
    x0 = np.full(a.n, 0.05)
    plant, twin, quantised = (make_plant("artifact", artifact=a, x0=x0) for _ in range(3))
    res = run_pil(
        a, plant=plant, steps=PIL_STEPS, reference=REFERENCES[name], board=board, twin=twin, check_plant=quantised
    )
    check, label = res.checks["fixed_point"], f"{name}-{numeric}/{board}"
    assert not np.any(res.flags & 0x01), f"{label}: a step was refused"
    assert check.bit_exact, f"{label}: the image differs from the model at {check.first_difference}"
    assert check.unsaturated_steps == PIL_STEPS and check.overflow_steps == 0, label
    assert check.within_bound, f"{label}: {check.measured_du_rounding} > {check.bound_du_float32_link}"
