"""Ctrl-C on the command line: exit status 130 (the shell's 128 + SIGINT), one line on stderr, never a traceback,
and no process of the command left running.

The first three tests run ``gainlink`` as its own process with a command whose work meets the interrupt where the
real ones met it (a finaliser, a clean-up that fails, an ``atexit`` handler); the SIGINT is real, sent by the
process to itself at that point. The others interrupt a real HIL run (firmware node, FMU) at two moments;
``tests/test_campaign.py`` interrupts campaigns (the cluster starting, runs in flight).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time

import pytest
from support.hil import pendulum_scenario, udp_transport, write_scenario
from support.procs import children_running, group_alive

# `gainlink hil fmu` with its work replaced by WORK, run as the process's own command (main() without argv, as the
# console script runs it). The parser is built after the replacement, so the subcommand calls WORK.
_COMMAND = """
import atexit, signal, sys
import gainlink.cli as cli
import gainlink.cli.hil as hil

def interrupt_here():
    signal.raise_signal(signal.SIGINT)  # a terminal's Ctrl-C, landing exactly here
    sum(range(100))                      # the next bytecodes, where Python runs the handler

WORK

hil._fmu = work
sys.argv = ["gainlink", "hil", "fmu"]
sys.exit(cli.main())
"""

_IN_A_FINALISER = """
class Finaliser:  # as pyparsing's Forward.__del__, which matplotlib's import ran when a Ctrl-C came
    def __del__(self):
        interrupt_here()

def work(args):
    Finaliser()
    for _ in range(10**7):  # the command's work goes on: the interrupt stops it here
        pass
    print("finished")
    return 0
"""

_CLEAN_UP_RAISES = """
def work(args):
    try:
        interrupt_here()
    finally:  # as Dask closing a cluster whose workers were still starting
        raise AssertionError("Status.init")
"""

_ATEXIT_RAISES = """
def close_clusters():  # as Dask's atexit closing of that cluster, again
    raise AssertionError("Status.init")

def work(args):
    atexit.register(close_clusters)
    interrupt_here()
    print("finished")
    return 0
"""


@pytest.mark.parametrize(
    "work",
    [
        pytest.param(_IN_A_FINALISER, id="in-a-finaliser"),
        pytest.param(_CLEAN_UP_RAISES, id="clean-up-raises"),
        pytest.param(_ATEXIT_RAISES, id="atexit-raises"),
    ],
)
def test_an_interrupt_wherever_it_lands_stops_the_command_with_130_and_one_line(work):
    res = subprocess.run(
        [sys.executable, "-c", _COMMAND.replace("WORK", work)],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert (res.returncode, res.stdout, res.stderr) == (130, "", "gainlink: interrupted\n")


def _firmware_started(pid: int) -> bool:
    return bool(children_running(pid, b"gainlink_can"))


@pytest.mark.parametrize("moment", ["mid-run", "after-the-loop"])
def test_ctrl_c_on_a_hil_run_exits_130_with_one_line_and_stops_the_firmware(
    tmp_path, pend, can_firmware, cart_fmu, moment
):
    # 60 s of lockstep steps take tens of seconds: mid-run is while the firmware node answers; after the loop is
    # once it stopped (a short run), while the twins, the report and the plots (matplotlib's import) are made
    duration = 60.0 if moment == "mid-run" else 2.0
    scenario = write_scenario(
        tmp_path / "hil.toml",
        pendulum_scenario(gains=pend, fmu=cart_fmu, transport=udp_transport(fd=False), duration=duration),
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; from gainlink.cli import main; sys.exit(main())"]
        + ["hil", "run", str(scenario), "--report", str(tmp_path / "report"), "--no-progress"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 120
        while not _firmware_started(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.002)
        assert _firmware_started(proc.pid), "the firmware node never started"
        if moment == "mid-run":
            time.sleep(0.5)
        else:
            while _firmware_started(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.002)
        assert proc.poll() is None, "the run ended before the interrupt"
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the command and its firmware node
        _, err = proc.communicate(timeout=60)
        deadline = time.monotonic() + 30
        while group_alive(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not group_alive(proc.pid), "a process of the run outlived it"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    assert (proc.returncode, err) == (130, "gainlink: interrupted\n")
    assert not (tmp_path / "report").exists()


def test_ctrl_c_on_firmware_run_stops_the_loop_and_exits_130(pend):
    # the host loop on stdin/stdout (a SIGTERM to the command alone exits 0: tests/test_firmware_host.py)
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; from gainlink.cli import main; sys.exit(main())"]
        + ["firmware", "run", str(pend)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert proc.stdout.readline().startswith(b"gainlink-loop pendulum ")  # the loop is up, reading stdin
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the command and the loop
        _, err = proc.communicate(timeout=30)
        deadline = time.monotonic() + 30
        while group_alive(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not group_alive(proc.pid), "the loop outlived the command"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    assert (proc.returncode, err) == (130, b"gainlink: interrupted\n")
