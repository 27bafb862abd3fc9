"""The target matrix (`make test-matrix`, marker ``matrix``; not part of `make test`): every example on every
board, replayed bit for bit against the host and run processor-in-the-loop; every observer form and
anti-windup mode (seeded random designs) on every Cortex-M core, bit for bit.

PIL's oracle is the host library fed the very samples the image received: the commands the image sent
back must equal the host's bit for bit, step by step, and the loop must stay within the float32 bound of
its float64 twin. Each build is cached, so a second run only replays.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from gainlink.engines import qemu as qemu_engine
from gainlink.engines.native import NativeLoop
from gainlink.firmware.targets import BOARDS, CORTEX_M_TARGETS
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.laws.lq.golden import EXAMPLES, random_cases
from support.designs import golden_examples

pytestmark = pytest.mark.matrix

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("u", "sat", "xh", "z", "fault")
RTOL = 1e-4  # float32 firmware against its float64 twin in closed loop (as tests/test_pil.py)
PIL_STEPS = 1000


@pytest.fixture(scope="module", autouse=True)
def _quiet_design_warnings():
    logging.disable(logging.WARNING)
    yield
    logging.disable(logging.NOTSET)


def _case(name: str):
    return next(c for c in golden_examples() if c.label == name)


def assert_bit_identical(a: dict, b: dict, label: str) -> None:
    for key in KEYS:
        assert np.array_equal(a[key].view(np.uint8), b[key].view(np.uint8)), f"{label}: {key} differs in its bits"


@pytest.mark.parametrize("board", list(BOARDS))
@pytest.mark.parametrize("example", EXAMPLES)
def test_example_replays_bit_for_bit_on_every_board(example, board):
    case = _case(example)
    Y = case.Y.copy()
    Y[17, 0] = np.nan
    host = NativeLoop(case.artifact).run_raw(Y, case.R)
    image = qemu_engine.run_raw(case.artifact, Y, case.R, board=board)
    assert_bit_identical(host, image, f"{example}/{board}")


@pytest.mark.parametrize("board", list(BOARDS))
@pytest.mark.parametrize("example", EXAMPLES)
def test_example_runs_pil_on_every_board(example, board):
    a = _case(example).artifact
    x0 = np.full(a.n, 0.05)
    res = run_pil(
        a,
        plant=make_plant("artifact", artifact=a, x0=x0),
        steps=PIL_STEPS,
        board=board,
        twin=make_plant("artifact", artifact=a, x0=x0),
    )
    assert not np.any(res.flags & 0x01), f"{example}/{board}: a step was refused"
    # the image's commands are the host library's for the same samples (as float32), bit for bit
    host = NativeLoop(a).run_raw(res.y.astype(np.float32).astype(float), np.broadcast_to(a.r_op, (PIL_STEPS, a.q)))
    assert np.array_equal(res.u.view(np.uint32), host["u"].view(np.uint32)), f"{example}/{board}"
    assert res.comparison.worst_du_rel <= RTOL, f"{example}/{board}: {res.comparison.worst_du_rel:.3g}"


@pytest.mark.parametrize("target", CORTEX_M_TARGETS)
def test_every_form_and_anti_windup_mode_bit_for_bit_on_every_core(target):
    """Twelve seeded random designs: both observer forms x none/clamp/backcalc, without and with an
    operating point, n from 2 to 12."""
    for case in random_cases(12):
        host = NativeLoop(case.artifact).run_raw(case.Y, case.R)
        image = qemu_engine.run_raw(case.artifact, case.Y, case.R, target=target)
        assert_bit_identical(host, image, f"{case.label}/{target}")


SERVING = [b.name for b in BOARDS.values() if b.serves]


@pytest.mark.parametrize("board", SERVING)
def test_the_image_on_every_serving_board_is_a_mavlink_and_slcan_node(pend, board):
    """HIL through the image's UART (MAVLink, then slcan) equals the host apps' closed loop bit for bit."""
    from gainlink.hil.loop.bridge import run_scenario
    from support.net import tcp_port, udp_port
    from support.uart import assert_same_closed_loop, scenario

    host = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port()}, controller="firmware"))
    url = f"tcp:127.0.0.1:{tcp_port()}"
    image = run_scenario(scenario(pend, {"kind": "mavlink", "url": url}, controller="qemu", board=board))
    assert_same_closed_loop(image, host)
    can_host = run_scenario(
        scenario(
            pend, {"interface": "udp_multicast", "channel": "239.74.163.63", "hop_limit": 0}, controller="firmware"
        )
    )
    channel = f"socket://127.0.0.1:{tcp_port()}"
    can_image = run_scenario(scenario(pend, {"interface": "slcan", "channel": channel}, controller="qemu", board=board))
    assert_same_closed_loop(can_image, can_host)
