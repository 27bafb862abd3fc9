"""The firmware's MAVLink app as the MAVLink tests drive it: started on a port of the test's own, its
parameters read, a closed loop run against it, and a second design of the pendulum to upload."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
from gainlink.firmware.mavlink_app import MavlinkFirmware
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.laws import design as design_spec
from gainlink.mavlink.link import MavLink
from gainlink.mavlink.params import Encoding
from gainlink.mavlink.session import ParamSession, ParamValue
from gainlink.proof.reference import ReferenceLoop
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping.artifact import Artifact
from gainlink.spec import parse_spec

from .net import udp_port
from .paths import EXAMPLES


def retuned_pendulum(path: Path) -> Path:
    """The pendulum designed again with other weights: same structure, other gains."""
    spec = tomllib.loads((EXAMPLES / "pendulum.toml").read_text())
    spec["controller"]["Q_diag"] = [40.0, 1.0, 300.0, 2.0]
    spec["controller"]["R_diag"] = [3.0]
    spec["integral"]["Q_diag"] = [12.0]
    artifact_mod.write(path, design_spec(parse_spec(spec)).artifact)
    return path


def start_firmware(exe: Path, storage: Path | None) -> tuple[MavlinkFirmware, int]:
    """Start the MAVLink app on a UDP port of this test's own; returns the app and the port."""
    port = udp_port()
    fw = MavlinkFirmware(exe, url=f"udpin:127.0.0.1:{port}", storage=storage)
    fw.start()
    return fw, port


def _url(port: int | str) -> str:
    """A UDP port of the host app, or a node's own URL (an image's ``tcp:`` UART) as it is."""
    return port if isinstance(port, str) else f"udpout:127.0.0.1:{port}"


def read_params(port: int | str) -> dict[str, ParamValue]:
    """Every parameter of the app listening on ``port`` (or at the URL ``port``; bytewise encoding, as the app
    packs them)."""
    with MavLink(_url(port)) as link:
        link.wait_heartbeat(timeout=5)
        s = ParamSession(link, target_system=1, target_component=1, encoding=Encoding.BYTEWISE)
        return s.read_all()


def closed_loop(
    port: int | str, art: Artifact, *, steps: int = 300, timeout: float = 2.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run the artifact's own discrete plant against the firmware over the HIL link (``port``: as read_params);
    return Y, R, U."""
    t = MavlinkTransport(url=_url(port), controller_url="", n_inputs=art.m, n_outputs=art.p, n_refs=art.q, ts=art.Ts)
    x = np.zeros(art.n)
    x[2] = 0.05  # pendulum tilted
    Y, R, U = np.zeros((steps, art.p)), np.full((steps, art.q), 0.2), np.zeros((steps, art.m))
    with t:
        t.send_frames(t.encode_reset(seq=0))
        assert t.receive_command(timeout=timeout) is not None
        u = np.zeros(art.m)
        for k in range(steps):
            y = art.Cd @ x + art.Dd @ u
            Y[k] = y.astype(np.float32)
            t.send_frames(t.encode_sample(seq=k + 1, y=Y[k], r=R[k]))
            c = t.receive_command(timeout=timeout)
            assert c is not None and c.seq == k + 1
            u = U[k] = c.u
            x = art.Ad @ x + art.Bd @ u
    return Y, R, U


def reference_u(art: Artifact, Y: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The float64 reference law's commands for samples ``Y`` and references ``R`` (rounded to float32 as sent)."""
    return ReferenceLoop(art).run(Y, R.astype(np.float32).astype(float)).u
