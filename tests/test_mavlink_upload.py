"""MAVLink upload to the real firmware app: parameter list, verified upload, commit, persist, restart,
and the loop running on the new gains (closed loop over the HIL link against the float64 reference)."""

from __future__ import annotations

import math
import re
import shutil
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest
from gainlink.firmware.mavlink_app import MavlinkFirmware, mavlink_executable
from gainlink.laws import design as design_spec
from gainlink.shipping import artifact as artifact_mod
from gainlink.shipping.artifact import Artifact, load
from gainlink.shipping.codegen import gain_set
from gainlink.spec import parse_spec
from support.cli import GAINLINK, assert_refused, gainlink_process, run_cli
from support.mavlink import closed_loop, read_params, reference_u, start_firmware
from support.net import udp_port

STEMS = {
    "AD": "Ad",
    "BD": "Bd",
    "CD": "Cd",
    "DD": "Dd",
    "K": "K",
    "L": "L",
    "M": "M",
    "CI": "Ci",
    "KI": "Ki",
    "KAW": "Kaw",
    "UMIN": "u_min",
    "UMAX": "u_max",
    "XH0": "xh0",
    "Z0": "z0",
    "UOP": "u_op",
    "YOP": "y_op",
}


def expected_value(art: Artifact, name: str) -> float:
    """The float32 number a parameter id names, read straight from the artifact."""
    if name == "GL_TS":
        return float(np.float32(art.Ts))
    m = re.fullmatch(r"GL_([A-Z0-9]+?)_(\d+)(?:_(\d+))?", name)
    assert m, name
    a = np.asarray(getattr(art, STEMS[m.group(1)]), dtype=float)
    idx = (int(m.group(2)),) if m.group(3) is None else (int(m.group(2)), int(m.group(3)))
    return float(np.float32(a[idx]))


def test_parameter_list_is_the_artifact(mavlink_exe, pend):
    art = load(pend)
    fw, port = start_firmware(mavlink_exe, None)
    try:
        params = read_params(port)
    finally:
        fw.stop()
    names = list(params)
    assert names[:7] == ["GL_DIM_N", "GL_DIM_M", "GL_DIM_P", "GL_DIM_Q", "GL_FORM", "GL_AW", "GL_HASH"]
    assert [params[n].value for n in names[:6]] == [art.n, art.m, art.p, art.q, 0, 2]
    assert params["GL_HASH"].value & 0xFFFFFFFF == gain_set(art).crc32
    assert [p.index for p in params.values()] == list(range(len(params)))
    assert all(p.count == len(params) for p in params.values())
    assert all(len(n) <= 16 for n in names)
    floats = {n: p for n, p in params.items() if p.ptype == 9}
    # every number of the loop: Ts, Ad Bd Cd Dd K L (no M: predictor form), Ci Ki Kaw, limits, xh0, z0, u_op, y_op
    n, m, p, q = art.n, art.m, art.p, art.q
    assert (
        len(floats) == 1 + n * n + n * m + p * n + p * m + m * n + n * p + q * p + m * q + q * m + 2 * m + n + q + m + p
    )
    for name, pv in floats.items():
        assert pv.value == expected_value(art, name), name
    assert floats["GL_K_0_3"].value == float(np.float32(art.K[0, 3]))


def test_upload_persists_survives_restart_and_the_loop_runs_the_new_gains(mavlink_exe, pend, retuned, tmp_path):
    old, new = load(pend), load(retuned)
    assert old.n == new.n and not np.allclose(old.K, new.K)
    storage = tmp_path / "params.txt"
    fw, port = start_firmware(mavlink_exe, storage)
    try:
        Y, R, U = closed_loop(port, old)
        np.testing.assert_allclose(U, reference_u(old, Y, R), atol=1e-4)

        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--persist")
        assert res.code == 0, res.err
        assert "gain set committed" in res.out and "persisted" in res.out
        assert re.search(r"^GL_K_0_0\s+K\[0,0\]\s+\S+ -> \S+$", res.out, re.M)

        Y, R, U = closed_loop(port, new)
        np.testing.assert_allclose(U, reference_u(new, Y, R), atol=1e-4)
        assert np.max(np.abs(U - reference_u(old, Y, R))) > 1e-2  # really the new gains, not the old ones
    finally:
        fw.stop()
    assert storage.is_file()

    fw, port = start_firmware(mavlink_exe, storage)  # a restart: values reloaded from the stored file
    try:
        assert "loaded parameters" in fw.stderr_text()
        params = read_params(port)
        assert params["GL_HASH"].value & 0xFFFFFFFF == gain_set(new).crc32
        assert params["GL_K_0_2"].value == float(np.float32(new.K[0, 2]))
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--dry-run")
        assert res.code == 0 and "dry run: 0 parameter(s) would change" in res.out
        # The same set again, with --persist: nothing is set or committed, and the vehicle's flash is not written
        # (it holds this set): the command says so, not "persisted"
        stored = storage.stat().st_mtime_ns, storage.read_bytes()
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--persist")
        assert res.code == 0, res.err
        assert res.out.startswith(
            f"nothing to upload: vehicle 1/1 (MAV_AUTOPILOT_GENERIC, a gainlink node) already holds {new.name} "
            f"sha256:{new.sha256[:12]}"
        )
        assert "persisted" not in res.out and "committed" not in res.out
        assert (storage.stat().st_mtime_ns, storage.read_bytes()) == stored
        Y, R, U = closed_loop(port, new)
        np.testing.assert_allclose(U, reference_u(new, Y, R), atol=1e-4)
    finally:
        fw.stop()


def test_stored_set_holds_exact_bits_and_a_tampered_file_is_refused_whole(mavlink_exe, pend, retuned, tmp_path):
    """The storage file carries each float32's bits (so a reload is exact); a file whose values no longer
    match its GL_HASH, or with a malformed line, is refused whole and the compiled set runs."""
    old, new = load(pend), load(retuned)
    storage = tmp_path / "params.txt"
    fw, port = start_firmware(mavlink_exe, storage)
    try:
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--persist")
        assert res.code == 0, res.err
    finally:
        fw.stop()
    text = storage.read_text("ascii")
    rows = dict(line.split() for line in text.splitlines() if not line.startswith("#"))
    assert int(rows.pop("GL_HASH"), 16) == gain_set(new).crc32
    for name, bits in rows.items():
        assert np.uint32(int(bits, 16)).view(np.float32) == np.float32(expected_value(new, name)), name
    k02 = rows["GL_K_0_2"]
    tampered = f"{int(k02, 16) ^ 1:08x}"  # one bit of one gain flipped: the CRC no longer matches
    for bad, why in (
        (text.replace(f"GL_K_0_2 {k02}", f"GL_K_0_2 {tampered}"), "refused by the loop's checks"),
        (text.replace(f"GL_K_0_2 {k02}", "GL_K_0_2 1.5"), "line"),
    ):
        storage.write_text(bad, "ascii")
        fw, port = start_firmware(mavlink_exe, storage)
        try:
            assert read_params(port)["GL_HASH"].value & 0xFFFFFFFF == gain_set(old).crc32
        finally:
            fw.stop()
        err = fw.stderr_text()
        assert f"ignoring {storage}" in err and why in err and "using the compiled gain set" in err, err
    storage.write_text("\n".join(reversed(text.splitlines())) + "\n", "ascii")  # other line order: same set
    fw, port = start_firmware(mavlink_exe, storage)
    try:
        assert read_params(port)["GL_HASH"].value & 0xFFFFFFFF == gain_set(new).crc32
    finally:
        fw.stop()


def test_dry_run_prints_the_diff_and_writes_nothing(mavlink_exe, pend, retuned):
    fw, port = start_firmware(mavlink_exe, None)
    try:
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--dry-run")
        assert res.code == 0, res.err
        changed = [line.split()[0] for line in res.out.splitlines() if "->" in line]
        assert "GL_K_0_0" in changed and "GL_TS" not in changed
        assert read_params(port)["GL_HASH"].value & 0xFFFFFFFF == gain_set(load(pend)).crc32
    finally:
        fw.stop()


def test_other_dimensions_are_refused_before_anything_is_written(mavlink_exe, pend, example_artifacts):
    fw, port = start_firmware(mavlink_exe, None)
    try:
        argv = ("mavlink", "upload", example_artifacts["wood_berry"], "--connect", f"udpout:127.0.0.1:{port}")
        res = assert_refused(argv, "other dimensions")
        assert "nothing was changed" in res.err
        assert read_params(port)["GL_HASH"].value & 0xFFFFFFFF == gain_set(load(pend)).crc32
    finally:
        fw.stop()


def test_params_command_lists_every_parameter(mavlink_exe, pend):
    fw, port = start_firmware(mavlink_exe, None)
    try:
        res = run_cli("mavlink", "params", "--connect", f"udpout:127.0.0.1:{port}")
    finally:
        fw.stop()
    assert res.code == 0, res.err
    rows = dict(line.split() for line in res.out.splitlines())
    art = load(pend)
    assert int(rows["GL_DIM_N"]) == art.n
    assert math.isclose(float(rows["GL_K_0_1"]), expected_value(art, "GL_K_0_1"), rel_tol=1e-8)


def test_upload_listening_for_a_vehicle_that_sends_to_us(mavlink_exe, retuned):
    """The firmware on ``udpout:`` sends its heartbeats to the uploader's ``udpin:`` port."""
    port = udp_port()
    fw = MavlinkFirmware(mavlink_exe, url=f"udpout:127.0.0.1:{port}").start()
    try:
        res = run_cli("mavlink", "upload", retuned, "--connect", f"udpin:127.0.0.1:{port}")
        assert res.code == 0, res.err
        assert "gain set committed" in res.out
    finally:
        fw.stop()
    assert "committed gain set" in fw.stderr_text()


def test_firmware_run_mavlink_command_persists_beside_the_artifact(mavlink_exe, pend, retuned, tmp_path):
    """`gainlink firmware run ARTIFACT --mavlink URL`: upload --persist, stop, start again: values reloaded, and the
    start-up line says that the persisted set runs, not the artifact's; --from-artifact starts on the artifact's
    set and leaves the persisted one stored."""
    art_path = tmp_path / "gains.json"
    shutil.copy(pend, art_path)
    old, new = load(pend), load(retuned)
    url = "udpout:127.0.0.1:{port}"
    rounds = (
        ([], gain_set(old), "artifact"),
        ([], gain_set(new), "persisted"),
        (["--from-artifact"], gain_set(old), "artifact"),
    )
    for round_, (extra, runs, which) in enumerate(rounds):
        port = udp_port()
        proc = subprocess.Popen(
            [str(GAINLINK), "firmware", "run", str(art_path), "--mavlink", f"udpin:127.0.0.1:{port}", *extra],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            banner = proc.stdout.readline()
            assert banner.startswith("gainlink-mavlink pendulum sha256:"), banner + proc.stderr.read()
            assert banner.rstrip().endswith(f" gains={which} crc32={runs.crc32} format=float32 law=float32 wire=4"), (
                banner
            )
            if round_ == 0:
                res = run_cli("mavlink", "upload", retuned, "--connect", url.format(port=port), "--persist")
                assert res.code == 0 and "persisted" in res.out, res.err
            else:
                art = new if which == "persisted" else old
                Y, R, U = closed_loop(port, art, steps=100)
                np.testing.assert_allclose(U, reference_u(art, Y, R), atol=1e-4)
                assert read_params(port)["GL_HASH"].value & 0xFFFFFFFF == runs.crc32
        finally:
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=10) == 0
            err = proc.stderr.read()
            proc.stdout.close()
            proc.stderr.close()
        assert (tmp_path / "mavlink_params.txt").is_file()
        assert ("loaded parameters from" in err) == (which == "persisted"), err
    stored = (tmp_path / "mavlink_params.txt").read_text("ascii")
    assert f"GL_HASH {gain_set(new).crc32:08x}" in stored  # --from-artifact kept the persisted set


def test_a_forced_encoding_that_contradicts_the_vehicles_is_refused_before_any_write(mavlink_exe, pend, retuned):
    """The app advertises bytewise integers: --encoding c_cast would write GL_HASH (and a fixed-point law's gains)
    as other numbers. One line, exit 2, nothing written."""
    fw, port = start_firmware(mavlink_exe, None)
    try:
        before = read_params(port)
        argv = (GAINLINK, "mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--encoding", "c_cast")
        phrase = "--encoding c_cast contradicts the vehicle's AUTOPILOT_VERSION, which advertises bytewise"
        assert_refused(argv, phrase, retuned.parent, process=True)
        after = read_params(port)
        assert {n: p.value for n, p in after.items()} == {n: p.value for n, p in before.items()}
        res = gainlink_process(
            "mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--encoding", "bytewise"
        )
        assert res.code == 0 and "gain set committed" in res.out, res.err
    finally:
        fw.stop()
    assert fw.counters()["refused_sets"] == 0


@pytest.mark.parametrize(
    "shape",
    [
        dict(n=3, m=2, p=2, q=0, form="current", anti_windup="none"),
        dict(n=5, m=2, p=3, q=2, form="current", anti_windup="clamp"),
    ],
)
@pytest.mark.slow
def test_firmware_and_python_naming_schemes_agree_for_every_structure(shape, tmp_path):
    """Current-estimator form (M present), no integral action (q = 0: CI KI KAW Z0 absent) and q = 2."""
    from gainlink.mavlink.params import firmware_params
    from gainlink.shipping.artifact import from_dict
    from gainlink.synthesis.random_plants import random_spec

    art = from_dict(design_spec(parse_spec(random_spec(11, **shape))).artifact)
    fw, port = start_firmware(mavlink_executable(art), None)
    try:
        got = read_params(port)
        res = run_cli(
            "mavlink", "upload", str(_write(art, tmp_path)), "--connect", f"udpout:127.0.0.1:{port}", "--dry-run"
        )
    finally:
        fw.stop()
    want = firmware_params(art)
    assert [(p.name, p.ptype) for p in got.values()] == [(s.name, s.ptype) for s in want]
    for s in want:
        if s.ptype == 9:
            assert got[s.name].value == expected_value(art, s.name) == s.value, s.name
    assert ("GL_M_0_0" in got) and (("GL_KI_1_1" in got) == (art.q == 2)) and (("GL_Z0_0" in got) == (art.q > 0))
    assert res.code == 0 and "dry run: 0 parameter(s) would change" in res.out


def _write(art: Artifact, tmp_path: Path) -> Path:
    path = tmp_path / "gains.json"
    artifact_mod.write(path, art.data)
    return path
