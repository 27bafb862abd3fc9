"""Real SocketCAN: the firmware's gainlink_can and the bridge on vcan0 inside a small Linux VM.

The host kernel has no CAN, so the test boots qemu-system-x86_64 (TCG) with Debian's kernel, a
busybox initramfs and the host root shared read-only over 9p (see gainlink.hil.links.vcan_vm), and runs the
same lockstep scenario there with ``interface = "socketcan", channel = "vcan0"`` that it runs on the
host over udp_multicast. Both runs must stabilise the nonlinear pendulum FMU from 0.1 rad and agree.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from gainlink.hil.links.vcan_vm import prepare_vm, run_in_vm
from gainlink.hil.loop.bridge import run_scenario
from gainlink.hil.loop.scenario import load_scenario
from support.hil import pendulum_scenario, udp_transport, write_scenario

pytestmark = pytest.mark.slow(cpu=58)  # the VM's boot and its Python under TCG


@pytest.mark.skipif(shutil.which("qemu-system-x86_64") is None, reason="qemu-system-x86 is installed by make setup")
def test_lockstep_over_vcan0_in_vm_matches_udp_multicast(tmp_path, pend, can_firmware, cart_fmu):
    image = prepare_vm()
    duration = 2.0
    udp = write_scenario(
        tmp_path / "udp.toml",
        pendulum_scenario(
            gains=pend,
            fmu=cart_fmu,
            transport=udp_transport(fd=True),
            duration=duration,
            firmware=str(can_firmware),
        ),
    )
    host = run_scenario(load_scenario(udp))
    assert host.complete, host.reason

    vm_dir = tmp_path / "vm"
    vm_dir.mkdir()
    write_scenario(
        vm_dir / "vcan.toml",
        pendulum_scenario(
            gains=pend,
            fmu=cart_fmu,
            duration=duration,
            firmware=str(can_firmware),
            transport={"interface": "socketcan", "channel": "vcan0", "fd": True},
            step_timeout=2.0,
            peer_timeout=20.0,
            # the float64 twins (a second FMU and the law around the model) are Python under emulation, and what
            # this test compares does not depend on them: the host run has them
            twin=False,
            model_twin=False,
        ),
    )
    gainlink = Path(sys.executable).parent / "gainlink"
    run = run_in_vm(
        f"{gainlink} hil run vcan.toml --report report --no-progress --no-plots > hil.log 2>&1\n",
        workdir=vm_dir,
        timeout=900,
        image=image,
    )
    log = (vm_dir / "hil.log").read_text() if (vm_dir / "hil.log").exists() else ""
    assert run.status == 0, f"VM run failed (status {run.status}):\n{log}\n{run.console[-2000:]}"
    vm = json.loads((vm_dir / "report" / "report.json").read_text())

    # Really SocketCAN on vcan0, against the firmware executable.
    assert vm["run"]["transport"]["config"] == {"interface": "socketcan", "channel": "vcan0", "fd": True}
    assert Path(vm["run"]["controller"]["argv"][0]).name == "gainlink_can"
    assert "--backend" in vm["run"]["controller"]["argv"] and "socketcan" in vm["run"]["controller"]["argv"]

    # Both runs stabilise the nonlinear pendulum from 0.1 rad ...
    n = int(round(duration / 0.01))
    for m in (host.metrics, vm):
        assert m["complete"] is True and m["steps"] == n and m["lost"] == 0 and m["late"] == 0
        assert abs(m["outputs_final"]["theta"]) < 0.02
    theta = host.trace.y[:, 1]
    assert abs(theta[0] - 0.1) < 1e-12 and np.abs(theta[n // 2 :]).max() < 0.05
    # ... and agree: same plant, same float32 firmware law, same frames -> the same trajectory.
    for name, value in host.metrics["outputs_final"].items():
        assert vm["outputs_final"][name] == pytest.approx(value, rel=1e-6, abs=1e-9)
    assert vm["saturation_fraction"] == host.metrics["saturation_fraction"]
    assert vm["tracked"]["r_x"]["iae"] == pytest.approx(host.metrics["tracked"]["r_x"]["iae"], rel=1e-6)
