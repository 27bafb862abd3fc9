"""The firmware's CAN node: the build of its executable, and ``gainlink firmware run ARTIFACT --can CONFIG``
which runs it on a configured bus.

CONFIG is a python-can configuration — a TOML or JSON file, or inline JSON — e.g.
``{"interface": "socketcan", "channel": "can0", "fd": true}`` or a ``udp_multicast`` group, with
gainlink's ``base_id``, ``encoding`` and ``ranges`` keys as in a scenario's transport table. The
node runs in the foreground until interrupted; a bench's bridge (``gainlink hil run``) talks to it.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from gainlink.errors import TransportError
from gainlink.fileio import read_user_file
from gainlink.shipping.artifact import load

from .can import config_from_text, firmware_can_argv, layout_from_config


def firmware_can_executable(artifact: Any) -> Path:
    """Build (cached) the host firmware for ``artifact`` and return its ``gainlink_can`` executable (the artifact's
    own law: float32, fixed point or scheduled)."""
    from gainlink.firmware.build import host_app

    return host_app(artifact, target="gainlink_can", relpath="apps/can/gainlink_can")


def read_can_config(text_or_path: str) -> dict:
    """A python-can configuration from a file (TOML/JSON) or inline JSON."""
    if text_or_path.lstrip().startswith("{"):
        return config_from_text(text_or_path, source="--can")
    path = Path(text_or_path)
    text = read_user_file(path, what="CAN configuration", error=TransportError)
    return config_from_text(text, source=str(path))


def run_firmware_can(*, artifact_path: str, can: str) -> int:
    """Build (cached) and exec ``gainlink_can`` for the artifact on the configured bus (does not return)."""
    artifact = load(artifact_path)
    config = read_can_config(can)
    argv = firmware_can_argv(config, layout=layout_from_config(config, artifact=artifact))
    exe = firmware_can_executable(artifact)
    sys.stdout.flush()
    sys.stderr.flush()
    os.execv(str(exe), [str(exe), *argv])  # the node replaces this process: signals reach it directly
    return 0  # not reached
