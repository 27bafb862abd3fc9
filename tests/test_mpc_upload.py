"""The MPC law's cached factors are its MAVLink parameter set (issue 32, "everywhere a law goes"): the firmware's
MAVLink node built from one design takes another design's factors (another rho: every per-stage gain K_k and
C1_k differs) in one signed, verified commit, refuses a set of another horizon before anything is written (the
horizon is in the compatibility check), and rolls a commit its own check refuses back to the set it runs.

Oracles: the parameter table rendered from the artifact (gainlink.shipping.params, the C descriptions) read back
whole; the float32 model of the C (gainlink.laws.mpc with the C's arithmetic, checked bit for bit against the host C
in tests/test_mpc.py) fed the samples sent over the HIL link.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gainlink.firmware.mavlink_app import MavlinkFirmware, mavlink_executable
from gainlink.hil.links.mavlink import MavlinkTransport
from gainlink.laws import law_of
from gainlink.mavlink import upload as upload_mod
from gainlink.mavlink.params import INT32, firmware_params
from gainlink.mavlink.signing import new_key, write_key
from gainlink.mavlink.upload import UploadFailed, upload
from gainlink.shipping.artifact import from_dict
from support.cli import assert_refused
from support.designs import designed
from support.mavlink import read_params
from support.mpc import mpc_pendulum
from support.net import udp_port

pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def _design(horizon: int = 5, rho: float | None = None):
    data = mpc_pendulum(horizon=horizon, box=2.5)
    if rho is not None:
        data["mpc"]["rho"] = rho
    return from_dict(designed(data))


def _expected(a) -> list[tuple[str, float]]:
    return [(s.name, int(s.value) if s.ptype == INT32 else float(np.float32(s.value))) for s in firmware_params(a)]


def _table(url: str) -> list[tuple[str, float]]:
    got = read_params(url)
    return [(k, float(got[k].value)) for k in sorted(got, key=lambda k: got[k].index)]


def _answers(url: str, a, samples: list[tuple[float, float]]) -> list[np.float32]:
    """The node's commands on these (x, theta) samples over its HIL link, from its reset."""
    with MavlinkTransport(url=url, controller_url="", n_inputs=1, n_outputs=2, n_refs=1, ts=a.Ts) as link:
        out = []
        for seq, (x, th) in enumerate(samples):
            link.send_frames(link.encode_sample(seq=seq, y=np.array([x, th]), r=np.array([0.0])))
            cmd = link.receive_command(timeout=3.0)
            assert cmd is not None, seq
            out.append(np.float32(cmd.u[0]))
    return out


def _model(a, samples) -> list[np.float32]:
    ctl = law_of(a).model(a)
    return [np.float32(ctl.step(np.array(s), np.array([0.0]), np.zeros(0)).u[0]) for s in samples]


def test_the_factors_upload_signed_verified_rolled_back_and_refused_for_another_horizon(tmp_path, monkeypatch):
    a, b = _design(), _design(rho=12.0)  # another rho: every cached factor differs
    c = _design(horizon=6)
    assert a.mpc.horizon == b.mpc.horizon and not np.allclose(a.mpc.C1, b.mpc.C1)
    key_file = write_key(tmp_path / "vehicle.key", new_key())
    key = bytes.fromhex(key_file.read_text())
    store, port = tmp_path / "params.txt", udp_port()
    fw = MavlinkFirmware(mavlink_executable(a), url=f"udpin:127.0.0.1:{port}", storage=store, signing_key=key_file)
    fw.start()
    url = f"udpout:127.0.0.1:{port}"
    try:
        assert _table(url) == _expected(a)
        c.save(tmp_path / "n6.json")
        argv = ("mavlink", "upload", tmp_path / "n6.json", "--connect", url, "--signing-key", key_file)
        assert_refused(argv, "GL_HORIZON", tmp_path / "n6.json")  # another horizon: refused before a write
        assert _table(url) == _expected(a)

        def wrong_hash(art):  # the node's own CRC check refuses the commit: every staged value must be undone
            return tuple(s if s.name != "GL_HASH" else dataclasses.replace(s, value=int(s.value) ^ 1)
                         for s in firmware_params(art))  # fmt: skip

        with monkeypatch.context() as m:
            m.setattr(upload_mod, "firmware_params", wrong_hash)
            with pytest.raises(UploadFailed) as failed:
                upload(b, connect=url, signing_key=key)
        assert failed.value.rolled_back and _table(url) == _expected(a)
        res = upload(b, connect=url, signing_key=key, persist=True)
        assert res.committed and res.persisted and len(res.changes) > 2 * a.mpc.horizon
        assert _table(url) == _expected(b)
    finally:
        fw.stop()
    assert fw.counters()["signing"] == 1 and fw.counters()["commits"] == 1  # the exit summary's
    fw = MavlinkFirmware(mavlink_executable(a), url=f"udpin:127.0.0.1:{port}", storage=store)
    fw.start()  # the stored set is loaded at start, and the law runs it (the HIL link here is unsigned)
    try:
        assert _table(url) == _expected(b)
        samples = [(0.05 - 0.005 * k, 0.002 * k) for k in range(8)]  # inside the box: the solver's iterates differ
        assert _answers(url, a, samples) == _model(b, samples) != _model(a, samples)
    finally:
        fw.stop()
