"""Every status bit on every link, from the real firmware: the host CAN node (gainlink_can on python-can
udp_multicast), the host MAVLink app (gainlink_mavlink over UDP) and the Cortex-M image's slcan and MAVLink nodes on
its UART in QEMU, each running each law that has bits: the float32 law (fault), the fixed-point law (fault, a sample
clipped to its range, and, with integers edited so that V leaves 32 bits, the second-line saturation) and the
scheduled law (fault, sigma held, clipped and rate-limited) and the MPC law (fault, and its solver stopped at the
cap: bit 8, which CAN carries in byte 3: its high nibble in a classic frame, the flags' bits 8-15 in an FD frame, wire
format 4); the host CAN node on classic frames and on CAN FD ones; over MAVLink also the watchdog (the CAN node steps
only on a sample: it has none).

Samples chosen so that each bit must be set (a NaN, a sample and a reference beyond their declared ranges, an
external sigma that is not finite, beyond the envelope and jumping faster than its rate limit, big errors for the
saturation) go through the link, and every answer's status, as the Python side decodes it, must be the bits the
law's own model gives for that sample (``tests/support/status.py``: the model's flags through the bit positions
docs/design.md documents, not through any table a link uses), with the command bit for bit the model's."""

from __future__ import annotations

import copy

import pytest
from gainlink.laws import design
from gainlink.shipping.artifact import Artifact, from_dict, load, seal
from gainlink.spec import load_spec
from schedule_cases import external_tank
from support.designs import designed
from support.fixed import example
from support.mavlink import start_firmware
from support.paths import EXAMPLES
from support.status import (
    CAPPED,
    CLIPPED,
    FAULT,
    OVERFLOW,
    SIGMA_BITS,
    WATCHDOG,
    assert_answers,
    can_node,
    image_node,
    mavlink_link,
)

# One worker runs this module (make test: --dist loadgroup), first: its laws' nodes are built once.
pytestmark = [
    pytest.mark.usefixtures("quiet_design_warnings"),
    pytest.mark.xdist_group("test_status_bits"),
    pytest.mark.slow(cpu=50),  # builds and runs on one worker, 50 CPU-s: started first (tests/conftest.py)
]

NAN = float("nan")

#: The pendulum (y = x, theta; r = r_x; declared ranges x +-2, theta +-0.5, r_x +-1; F within +-20 N).
PENDULUM = [
    ((0.1, 0.02), 0.2, ()),
    ((0.0, 0.4), 0.0, ()),
    ((NAN, 0.0), 0.0, ()),  # refused: fault, the safe command
    ((0.0, 3.0), 0.0, ()),  # theta beyond its range: clipped (fixed point); F saturates
    ((0.0, 0.01), 2.5, ()),  # r_x beyond its range
    ((0.05, -0.01), 0.1, ()),
]

#: The tank scheduled on an external load (y = h, r = r_h, s = load; points 0.04, 0.25, 1; sigma filtered with a
#: 0.1 s time constant and rate-limited to 4/s, 0.2 a step).
TANK = [
    (0.3, 0.3, 0.1),  # the start
    (0.3, 0.3, NAN),  # sigma not finite: held
    (0.3, 0.3, 1.0),  # a jump the filter passes at 0.35 a step: rate-limited
    (0.3, 0.3, 1.6),  # beyond the envelope: clipped (and still rate-limited)
    (0.3, 0.3, 1.6),
    (0.3, 0.3, 1.6),
    (NAN, 0.3, 0.5),  # refused: fault, u_op at the held sigma
    (0.3, 3.0, 0.6),  # a big error: the pump saturates at the next step
    (0.3, 3.0, 0.6),
]

#: The MPC pendulum (examples/pendulum_mpc.toml: y = x, theta; r = r_x; +-20 N): from its start the first step stops
#: at once, then 1 m off the cap stops the solver (CAPPED, 0x100: the status word's bit 8, on CAN in byte 3), a NaN is
#: refused.
MPC = [
    ((1.0, 0.0), 0.0, ()),
    ((1.0, 0.0), 0.0, ()),  # capped
    ((NAN, 0.0), 0.0, ()),  # refused: fault, the safe command
    ((0.9, 0.05), 0.0, ()),  # capped
]

#: Law -> (the samples, the status bits they must show on every link).
LAWS = {
    "float32": (PENDULUM, FAULT),
    "q31": (PENDULUM, FAULT | CLIPPED),
    "q31_overflow": (PENDULUM, FAULT | CLIPPED | OVERFLOW),
    "scheduled": (TANK, FAULT | sum(SIGMA_BITS.values())),
    "mpc": (MPC, FAULT | CAPPED),
}


def _overflowing(a: Artifact) -> Artifact:
    """The q31 pendulum with integers that no longer keep V within 32 bits (KX XH0 = 2^62 at the first step, as in
    tests/test_fixed_c.py): the C saturates V and flags it, as the model does."""
    data = copy.deepcopy(a.data)
    integers = data["checks"]["fixed_point"]["integers"]
    integers["KX"][0][1] = integers["XH0"][1] = 2**31 - 1
    return from_dict(seal(data))


@pytest.fixture(scope="module")
def laws(pend) -> dict[str, Artifact]:
    q31 = example("pendulum", "q31")
    return {
        "float32": load(pend),
        "q31": q31,
        "q31_overflow": _overflowing(q31),
        "scheduled": from_dict(designed(external_tank(form="current", rate_max=4.0, filter_tau=0.1))),
        "mpc": from_dict(design(load_spec(EXAMPLES / "pendulum_mpc.toml")).artifact),
    }


def _check(a: Artifact, law: str, transport, *, mavlink: bool) -> None:
    samples, bits = LAWS[law]
    seen = assert_answers(a, transport, samples, mavlink=mavlink)
    assert seen == bits | (WATCHDOG if mavlink else 0), f"{law}: the link showed {seen:#04x}"


@pytest.mark.parametrize("fd", [False, True], ids=["classic", "fd"])
@pytest.mark.parametrize("law", list(LAWS))
def test_the_host_can_node_sends_each_bit_its_law_sets(laws, law, fd):
    """Classic frames and CAN FD frames (wire format 4: their headers differ), the same bits."""
    from gainlink.hil.links.can_firmware import firmware_can_executable

    a = laws[law]
    with can_node(a, firmware_can_executable(a), fd=fd) as transport:
        _check(a, law, transport, mavlink=False)


@pytest.mark.parametrize("law", list(LAWS))
def test_the_host_mavlink_app_sends_each_bit_its_law_sets(laws, law):
    """The overflowing integers reach the q31 app as an upload (it takes any integers within their words)."""
    from gainlink.firmware.mavlink_app import mavlink_executable
    from gainlink.mavlink.upload import upload

    a = laws[law]
    fw, port = start_firmware(mavlink_executable(laws["q31"] if law == "q31_overflow" else a), None)
    try:
        url = f"udpout:127.0.0.1:{port}"
        if law == "q31_overflow":
            assert upload(a, connect=url).committed
        with mavlink_link(a, url) as transport:
            _check(a, law, transport, mavlink=True)
    finally:
        fw.stop()


#: The boards the other UART tests build each law's image for (tests/test_target_uart*.py, test_sched_target_uart.py).
BOARDS = {"float32": "mps2-an386", "q31": "mps2-an385", "q31_overflow": "mps2-an385", "scheduled": "mps2-an386",
          "mpc": "mps2-an386"}  # fmt: skip


@pytest.mark.parametrize("protocol", ["slcan", "mavlink"])
@pytest.mark.parametrize("law", list(LAWS))
def test_the_cortex_m_images_nodes_send_each_bit_their_law_sets(laws, law, protocol):
    a = laws[law]
    with image_node(a, board=BOARDS[law], protocol=protocol) as transport:
        _check(a, law, transport, mavlink=protocol == "mavlink")
