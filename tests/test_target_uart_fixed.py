"""The Cortex-M image's slcan node runs a fixed-point artifact's integer law, not the float law of the same export;
its MAVLink node too, and takes a re-designed set of integers over the UART as the host app does.

On the cores without an FPU, where fixed point matters (M3: mps2-an385; M0: the micro:bit, whose 16 KiB of RAM
hold the slcan node of a fixed-point export but not the MAVLink node), the q31 pendulum is served by the image over
slcan in QEMU, in closed loop with the cart-pendulum FMU. Oracles: the host CAN app on the same scenario (the same C,
so the same closed loop bit for bit), and the bit-exact integer model (``gainlink.laws.fixed.model``) on the samples
the image received.
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest
from gainlink.errors import FirmwareError
from gainlink.firmware.build import build
from gainlink.firmware.uart import QemuUart
from gainlink.hil.loop.bridge import run_scenario
from gainlink.laws.fixed.model import FixedPointLoop
from gainlink.laws.fixed.qformat import real
from gainlink.laws.lq.model import Float32Loop
from gainlink.mavlink.params import firmware_params as fixed_firmware_params
from support.cli import assert_refused, run_cli
from support.fixed import example, model_run, pendulum_design
from support.hil import udp_transport
from support.mavlink import closed_loop, read_params
from support.net import tcp_port, udp_port
from support.uart import assert_same_closed_loop, scenario

CORES = {"mps2-an385": "cortex-m3", "microbit": "cortex-m0"}
# The one variant of the law each serving image links (ports/cortex-m/cortex-m.cmake names it): the MAVLink node's
# generic one where the image carries that node (the slcan node runs it too), the unrolled one on the micro:bit.
FIXED_LIBRARY = {"mps2-an385": "libgainlink_loop_generic.a", "microbit": "libgainlink_loop.a"}
VARIANT = {"mps2-an385": "generic", "microbit": "unrolled"}


@pytest.fixture(scope="module")
def q31_saved(tmp_path_factory):
    """The pendulum designed in q31, saved."""
    a = example("pendulum", "q31")
    path = tmp_path_factory.mktemp("q31img") / "gains.json"
    a.save(path)
    return a, path


@pytest.fixture(scope="module")
def q31(q31_saved):
    """The q31 pendulum and its host CAN app's run of the scenario (the oracle)."""
    a, path = q31_saved
    host = run_scenario(scenario(path, udp_transport(fd=False), controller="firmware", duration=1.0))
    return a, path, host


@pytest.mark.parametrize("board", list(CORES))
def test_the_images_slcan_node_runs_the_integer_law_bit_for_bit(q31, board):
    a, path, host = q31
    image_map = build(a, target=CORES[board], board=board).files["map"].read_text()  # cached
    assert set(re.findall(r"(lib\w+\.a)\(gl_fixed\.c\.obj\)", image_map)) == {FIXED_LIBRARY[board]}
    slcan = {"interface": "slcan", "channel": f"socket://127.0.0.1:{tcp_port()}"}
    image = run_scenario(scenario(path, slcan, controller="qemu", board=board, duration=1.0))
    assert_same_closed_loop(image, host)  # the host CAN app, which runs the integer law (tests/test_can_laws.py)
    assert image.info["controller"]["ready"].startswith(f"gainlink pendulum {board} sha256:{a.sha256}")
    assert (
        "law=q31" in image.info["controller"]["ready"]
        and f"variant={VARIANT[board]}" in image.info["controller"]["ready"]
    )
    Y, R = image.trace.y.astype(np.float32), image.trace.r.astype(np.float32)
    model = model_run(a, Y, R)
    u_model = real(model.U, FixedPointLoop(a).f["u"]).astype(np.float32)
    np.testing.assert_array_equal(image.trace.u.astype(np.float32).view(np.uint32), u_model.view(np.uint32))
    assert not model.fault.any() and not image.trace.flags.any()
    f32 = Float32Loop(a).run(Y.astype(np.float64), R.astype(np.float64))  # not the export's float law
    assert np.any(f32.u.astype(np.float32) != image.trace.u.astype(np.float32))
    # The HIL report names the law that ran and checks it (gainlink.laws.fixed.run).
    fx = image.metrics["fixed_point"]
    assert fx["law"] == "q31" and fx["bit_exact"] is True and fx["overflow_steps"] == 0
    assert fx["within_per_step"] and fx["unsaturated_steps"] > 50


def test_the_microbits_image_refuses_mavlink_in_one_line(q31_saved):
    """Its 16 KiB hold the slcan node of a fixed-point export, not the MAVLink node: `serve mavlink` says so."""
    elf = build(q31_saved[0], target="cortex-m0", board="microbit").files["elf"]
    image = QemuUart(elf, board="microbit", protocol="mavlink", port=tcp_port(), lifetime_s=60)
    try:
        with pytest.raises(FirmwareError, match="refused its options: this image carries the slcan node only"):
            image.start()
        assert image.exit_status() is not None
    finally:
        image.close()


def test_the_m3_images_mavlink_node_runs_the_integer_law_bit_for_bit(q31_saved):
    """The MAVLink node of the M3's image, against the host MAVLink app of the same export and the integer model."""
    a, path = q31_saved
    url = f"tcp:127.0.0.1:{tcp_port()}"
    image = run_scenario(scenario(path, {"kind": "mavlink", "url": url}, controller="qemu", board="mps2-an385"))
    host = run_scenario(scenario(path, {"kind": "mavlink", "port": udp_port()}, controller="firmware"))
    assert_same_closed_loop(image, host)
    assert "law=q31" in image.info["controller"]["ready"] and "law=q31" in host.info["controller"]["ready"]
    Y, R = image.trace.y.astype(np.float32), image.trace.r.astype(np.float32)
    u_model = real(model_run(a, Y, R).U, FixedPointLoop(a).f["u"]).astype(np.float32)
    np.testing.assert_array_equal(image.trace.u.astype(np.float32).view(np.uint32), u_model.view(np.uint32))
    fx = image.metrics["fixed_point"]
    assert fx["law"] == "q31" and fx["bit_exact"] is True and fx["within_per_step"]


def test_the_microbit_serves_only_a_fixed_point_artifact_over_slcan_and_says_so(
    q31_saved, pend, pendulum_artifact, tmp_path
):
    mav = scenario(q31_saved[1], {"kind": "mavlink", "url": "tcp:127.0.0.1:1"}, controller="qemu", board="microbit")
    slcan = {"interface": "slcan", "channel": "socket://127.0.0.1:1"}
    for sc in (mav, scenario(pend, slcan, controller="qemu", board="microbit")):  # MAVLink; a float32 artifact
        with pytest.raises(FirmwareError, match=r"no bus node for this artifact and link .* for the q31 and q15 laws"):
            run_scenario(sc)
    can = '{"interface": "slcan", "channel": "socket://127.0.0.1:1"}'
    argv = ("firmware", "run", pendulum_artifact, "--target", "cortex-m0", "--can", can)
    assert_refused(argv, "holds only the slcan node, for the q31 and q15 laws", tmp_path)


# -- a re-designed set of integers uploaded to the M3 image's MAVLink node ------------------------------------------


@pytest.fixture(scope="module")
def retuned_q31(tmp_path_factory):
    """The q31 pendulum designed again with slightly other weights: the same formats and structure, other integers
    (as tests/test_mavlink_fixed.py uploads to the host app)."""
    a = pendulum_design("q31", [12.0, 1.0, 110.0, 1.0])
    path = tmp_path_factory.mktemp("retuned_q31img") / "gains.json"
    a.save(path)
    return a, path


def _m3_image(a, flash) -> QemuUart:
    elf = build(a, target="cortex-m3", board="mps2-an385").files["elf"]  # cached: the MAVLink test's image
    return QemuUart(elf, board="mps2-an385", protocol="mavlink", port=tcp_port(), flash_dir=flash, lifetime_s=300)


def _image_u(url: str, a, steps: int):
    """The image against ``a``'s discrete plant over its UART: the samples, references and its float32 commands."""
    Y, R, U = closed_loop(url, a, steps=steps, timeout=15.0)  # generous: a loaded VM stalls QEMU
    return Y, R, U.astype(np.float32)


def _model_u(a, Y, R) -> np.ndarray:
    return real(model_run(a, Y, R).U, FixedPointLoop(a).f["u"]).astype(np.float32)


def _integers(url: str) -> dict[str, int]:
    return {n: int(p.value) for n, p in read_params(url).items()}


def test_a_redesigned_q31_set_uploaded_to_the_m3_image_commits_runs_bit_for_bit_and_survives_a_restart(
    q31_saved, retuned_q31, tmp_path
):
    (old, _), (new, new_path) = q31_saved, retuned_q31
    want = {s.name: int(s.value) for s in fixed_firmware_params(new)}
    assert want != {s.name: int(s.value) for s in fixed_firmware_params(old)}
    flash = tmp_path / "flash"
    with _m3_image(old, flash) as image:
        assert "law=q31" in image.ready_line
        t0 = time.monotonic()
        res = run_cli("mavlink", "upload", new_path, "--connect", image.url, "--persist")
        took = time.monotonic() - t0
        assert res.code == 0, res.err
        assert "gain set committed" in res.out and "persisted" in res.out, res.out
        changed = re.findall(r"^GL_\w+\s+\S+\s+-?\d+ -> -?\d+$", res.out, re.M)
        print(f"upload to the M3 image: {len(changed)} of {len(want)} integers changed, {took:.2f} s")
        assert changed and _integers(image.url) == want
        Y, R, u = _image_u(image.url, new, 100)
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(new, Y, R).view(np.uint32))
        assert np.any(u != _model_u(old, Y, R))  # really the new integers
    assert (flash / "gl_flash.txt").is_file()

    with _m3_image(old, flash) as image:  # the board powered again: the integers come back from flash
        assert f"crc32={want['GL_HASH'] & 0xFFFFFFFF}" in image.ready_line, image.ready_line
        assert _integers(image.url) == want
        Y, R, u = _image_u(image.url, new, 40)
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(new, Y, R).view(np.uint32))


def test_the_m3_image_refuses_a_set_for_another_law_or_other_formats_in_one_line_and_nothing_changes(
    q31_saved, tmp_path
):
    old = q31_saved[0]
    other_formats = pendulum_design("q31", [40.0, 1.0, 300.0, 2.0], [3.0])
    assert other_formats.checks["fixed_point"]["signature"] != old.checks["fixed_point"]["signature"]
    pendulum_design("q15").save(tmp_path / "q15.json")
    other_formats.save(tmp_path / "formats.json")
    with _m3_image(old, tmp_path / "flash") as image:
        before = _integers(image.url)
        for name, why in (
            ("q15.json", "the firmware runs the q31 law and the artifact is a q15 design"),
            ("formats.json", "the firmware's q31 law has other number formats (GL_FX_SIG "),
        ):
            res = assert_refused(
                ("mavlink", "upload", tmp_path / name, "--connect", image.url, "--persist"), why, tmp_path
            )
            assert "nothing was changed" in res.err and res.out == ""
        assert _integers(image.url) == before
        Y, R, u = _image_u(image.url, old, 40)  # still the compiled integers
        np.testing.assert_array_equal(u.view(np.uint32), _model_u(old, Y, R).view(np.uint32))
    assert not (tmp_path / "flash" / "gl_flash.txt").exists()
