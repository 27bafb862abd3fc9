"""HIL over MAVLink: the same scenario (cart-pendulum FMU against the firmware) runs over the MAVLink
transport and over CAN (udp_multicast), and the two runs agree step for step."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from gainlink.errors import TransportError
from gainlink.hil.links.config import transport_from_config
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import parse_scenario
from gainlink.mavlink.signing import new_key, write_key
from support.hil import udp_transport
from support.net import udp_port


def scenario(artifact_path, transport: dict, **extra):
    data = {
        "name": "pendulum_link",
        "artifact": str(artifact_path),
        "duration": 3.0,
        "mode": "lockstep",
        "controller": "firmware",
        "step_timeout": 2.0,  # generous: elapses only on a real loss (the drop test passes its own)
        "seed": 5,
        "twin": True,
        "plant": {"kind": "fmu", "fmu": "cart_pendulum", "outputs": ["x", "theta"]},
        "transport": transport,
        "initial_state": {"theta": 0.1},
        "reference": {"r_x": {"kind": "step", "at": 0.5, "value": 0.5}},
        "noise": {"theta": 0.001},
        **extra,
    }
    return parse_scenario(data, path=artifact_path.parent / "scenario.toml")


def test_the_same_scenario_over_mavlink_and_can_agrees_step_for_step(pend):
    mav = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port()}))
    can = run_scenario(scenario(pend, udp_transport(fd=False)))
    assert mav.complete and can.complete, (mav.reason, can.reason)
    assert mav.info["transport"]["kind"] == "mavlink"
    assert "gainlink_mavlink" in mav.info["controller"]["argv"][0]
    assert mav.metrics["lost"] == 0 and mav.metrics["steps"] == 300
    assert mav.trace.got.all()
    # the firmware's float32 loop against its float64 twin: float32 accuracy (1e-4 of the limit span)
    assert mav.metrics["twin"]["worst_du_rel"] < 1e-4 and mav.metrics["twin"]["worst_dy_rel"] < 1e-4
    # both links carry float32 samples and commands unchanged: identical closed loops
    np.testing.assert_array_equal(mav.trace.u, can.trace.u)
    np.testing.assert_array_equal(mav.trace.y, can.trace.y)


def test_dropped_samples_over_mavlink_are_counted_and_the_loop_recovers(pend):
    # each dropped sample costs one step_timeout; 0.3 s outlasts this shared VM's stalls (30-300 ms), so
    # only the ten dropped samples go unanswered
    res = run_scenario(
        scenario(
            pend,
            {"kind": "mavlink", "port": udp_port()},
            step_timeout=0.3,
            peer_timeout=5.0,
            faults=[{"kind": "drop", "start": 1.0, "stop": 1.1, "every": 1}],
        )
    )
    assert res.complete, res.reason
    assert res.metrics["lost"] == 10
    np.testing.assert_array_equal(np.flatnonzero(~res.trace.got), np.arange(100, 110))
    assert abs(res.metrics["outputs_final"]["theta"]) < 0.05


def test_a_controller_with_another_key_stops_the_run_saying_its_messages_were_refused(pend, mavlink_exe, tmp_path):
    """The host app signs with a key that is not the link's: it refuses every sample and the bridge every
    message of it; the run ends as a silent controller, and its reason says what the link heard."""
    link_key, app_key = write_key(tmp_path / "link.key", new_key()), write_key(tmp_path / "app.key", new_key())
    app = tmp_path / "app_with_another_key"  # the real app, its --signing-key argument swapped
    app.write_text(
        f"#!{sys.executable}\nimport os, sys\nargv = sys.argv[1:]\n"
        f"argv[argv.index('--signing-key') + 1] = {str(app_key)!r}\n"
        f"os.execv({str(mavlink_exe)!r}, [{str(mavlink_exe)!r}, *argv])\n"
    )
    app.chmod(0o755)
    link = {"kind": "mavlink", "port": udp_port(), "signing_key": str(link_key)}
    res = run_scenario(scenario(pend, link, firmware=str(app), step_timeout=0.2, peer_timeout=1.5))
    assert not res.complete and res.metrics["steps"] < 20 and not res.trace.got.any()
    assert res.reason.startswith("controller silent for 1.5 s since step "), res.reason
    assert "the link got 0 command(s) and" in res.reason and "refused for a missing or wrong signature" in res.reason
    assert res.info["transport"]["unsigned_or_bad_answers"] > 0


def test_bad_mavlink_transport_tables_are_one_clear_error(pend):
    from gainlink.shipping.artifact import load

    art = load(pend)
    with pytest.raises(TransportError, match="unknown key"):
        transport_from_config({"kind": "mavlink", "baud": 5}, artifact=art)
    with pytest.raises(TransportError, match="port must be an integer"):
        transport_from_config({"kind": "mavlink", "port": "x"}, artifact=art)
    with pytest.raises(TransportError, match="expected udpout:HOST:PORT"):
        transport_from_config({"kind": "mavlink", "url": "serial:/dev/ttyACM0"}, artifact=art)
    with pytest.raises(TransportError, match="takes no port or controller_url"):
        transport_from_config({"kind": "mavlink", "url": "tcp:127.0.0.1:5760", "port": 5}, artifact=art)
    with pytest.raises(TransportError, match="busy_poll_us must be an integer"):
        transport_from_config({"kind": "mavlink", "busy_poll_us": -5}, artifact=art)


def test_busy_polling_over_mavlink_changes_timing_only(pend):
    common = dict(duration=1.0, twin=False)
    plain = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port()}, **common))
    busy = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port(), "busy_poll_us": 100}, **common))
    assert "--spin-us" not in plain.info["controller"]["argv"]
    assert busy.info["controller"]["argv"][-2:] == ["--spin-us", "100"]
    assert busy.info["transport"]["busy_poll_us"] == 100
    assert plain.complete and busy.complete, (plain.reason, busy.reason)
    assert plain.metrics["lost"] == 0 and busy.metrics["lost"] == 0 and busy.metrics["steps"] == 100
    # Lockstep is deterministic: the same samples give the same commands, however they are waited for.
    np.testing.assert_array_equal(plain.trace.u, busy.trace.u)
    np.testing.assert_array_equal(plain.trace.y, busy.trace.y)


def test_the_python_reference_node_over_mavlink_matches_the_firmware(pend):
    ref = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port()}, controller="reference"))
    fw = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port()}))
    assert ref.complete and fw.complete, (ref.reason, fw.reason)
    assert "gainlink.hil.links.mavlink_node" in ref.info["controller"]["argv"]
    assert "python reference" in ref.info["controller"]["ready"]
    # the report names the set the firmware ran: the artifact's (its CRC-32 from the gain set, not from the app)
    from gainlink.shipping.artifact import load
    from gainlink.shipping.codegen import gain_set

    crc = gain_set(load(pend)).crc32
    assert fw.info["controller"]["gains"] == {"set": "artifact", "crc32": crc, "format": "float32"}
    assert ref.trace.got.all() and ref.metrics["lost"] == 0
    # the node is the reference law: only the link's float32 values separate its loop from the float64 twin
    assert ref.metrics["twin"]["worst_du_rel"] < 1e-5
    np.testing.assert_allclose(fw.trace.u, ref.trace.u, atol=1e-3)  # float32 firmware vs float64 node
