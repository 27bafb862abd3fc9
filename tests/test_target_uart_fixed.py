"""The Cortex-M image's slcan node runs a fixed-point artifact's integer law, not the float law of the same export.

On the M3 (mps2-an385, no FPU: where fixed point matters) the q31 pendulum is served by the image over slcan in
QEMU, in closed loop with the cart-pendulum FMU. Oracles: the host CAN app on the same scenario (the same C, so the
same closed loop bit for bit), and the bit-exact integer model (``gainlink.proof.fixed_law``) on the samples the
image received. The micro:bit (M0) carries no bus node: its 16 KiB of RAM hold the replay image only.
"""

from __future__ import annotations

import numpy as np
import pytest
from gainlink.firmware.build import build
from gainlink.hil.loop.bridge import run_scenario
from gainlink.proof.fixed_format import real
from gainlink.proof.fixed_law import FixedPointLoop
from gainlink.proof.float32_law import Float32Loop
from support.fixed import example, model_run
from support.hil import udp_transport
from support.net import tcp_port
from support.uart import assert_same_closed_loop, scenario

BOARD = "mps2-an385"


@pytest.fixture(scope="module")
def q31(tmp_path_factory):
    """The pendulum designed in q31, saved, with its M3 serving image built (cached)."""
    a = example("pendulum", "q31")
    path = tmp_path_factory.mktemp("q31img") / "gains.json"
    a.save(path)
    build(a, target="cortex-m3", board=BOARD)
    return a, path


def _slcan(path):
    return {"interface": "slcan", "channel": f"socket://127.0.0.1:{tcp_port()}"}


def test_the_m3_images_slcan_node_runs_the_integer_law_bit_for_bit(q31):
    a, path = q31
    image = run_scenario(scenario(path, _slcan(path), controller="qemu", board=BOARD, duration=1.0))
    host = run_scenario(scenario(path, udp_transport(fd=False), controller="firmware", duration=1.0))
    assert_same_closed_loop(image, host)  # the host CAN app, which runs the integer law (tests/test_can_laws.py)
    assert "law=q31" in image.info["controller"]["ready"]
    Y, R = image.trace.y.astype(np.float32), image.trace.r.astype(np.float32)
    model = model_run(a, Y, R)
    u_model = real(model.U, FixedPointLoop(a).f["u"]).astype(np.float32)
    np.testing.assert_array_equal(image.trace.u.astype(np.float32).view(np.uint32), u_model.view(np.uint32))
    assert not model.fault.any() and not image.trace.status.any()
    f32 = Float32Loop(a).run(Y.astype(np.float64), R.astype(np.float64))  # not the export's float law
    assert np.any(f32.u.astype(np.float32) != image.trace.u.astype(np.float32))
    # The HIL report names the law that ran and checks it (hil/loop/can_fixed.py).
    fx = image.metrics["fixed_point"]
    assert fx["law"] == "q31" and fx["bit_exact"] is True and fx["overflow_steps"] == 0
    assert fx["within_per_step"] and fx["unsaturated_steps"] > 50
