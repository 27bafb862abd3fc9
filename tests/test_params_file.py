"""QGroundControl's ``.params`` files: ``gainlink mavlink params`` writes a vehicle's or an artifact's parameters in
that format and reads such files back; ``mavlink upload --dry-run --against FILE`` diffs an artifact against one.

Oracles: the artifact's own matrices rounded to float32 (what each parameter id names, by its id), a file in the
format QGroundControl writes (its header and 18-decimal floats, written here by hand), and the real MAVLink app: the
diff against the file saved from it is the diff against the app itself.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gainlink.mavlink.params_file import format_value, read_params_file
from gainlink.shipping.artifact import load
from support.cli import assert_refused, run_cli
from support.mavlink import start_firmware

GAINLINK = str(Path(sys.executable).with_name("gainlink"))

#: What QGroundControl writes when it saves a vehicle's parameters (ParameterManager), for an ArduPilot copter.
QGC_FILE = """\
# Onboard parameters for Vehicle 1
#
# Stack: ArduPilot
# Vehicle: Multi-Rotor
# Version: 4.5.7
# Git Revision: 2a3dc4b7
#
# Vehicle-Id Component-Id Name Value Type
1\t1\tACRO_BAL_PITCH\t1.000000000000000000\t9
1\t1\tATC_RAT_RLL_P\t0.135000005364418030\t9
1\t1\tFS_GCS_ENABLE\t0\t2
1\t1\tSERIAL0_BAUD\t115\t6
"""


def _matrix_value(a, name: str) -> float:
    """The float32 number the firmware's parameter id GL_<MATRIX>_i_j holds, from the artifact (by its id)."""
    m = re.fullmatch(r"GL_(AD|BD|CD|DD|K|L|CI|KI|KAW)_(\d+)_(\d+)", name)
    attr = {"AD": "Ad", "BD": "Bd", "CD": "Cd", "DD": "Dd", "K": "K", "L": "L", "CI": "Ci", "KI": "Ki", "KAW": "Kaw"}
    return float(np.float32(np.asarray(getattr(a, attr[m.group(1)]))[int(m.group(2)), int(m.group(3))]))


def test_an_artifacts_parameters_are_written_as_qgroundcontrol_reads_them_and_read_back(pend, tmp_path):
    path = tmp_path / "pendulum.params"
    res = run_cli("mavlink", "params", pend, "--out", path)
    assert res.code == 0, res.err
    text = path.read_text()
    lines = text.splitlines()
    assert lines[0] == "# Onboard parameters for Vehicle 1" and lines[2] == "# Stack: gainlink firmware (law float32)"
    assert lines[7] == "# Vehicle-Id Component-Id Name Value Type"
    rows = [ln.split("\t") for ln in lines[8:]]
    assert all(len(r) == 5 and r[:2] == ["1", "1"] for r in rows)
    a = load(pend)
    back = read_params_file(path)
    assert back.law == "float32" and [e.name for e in back.entries] == [r[2] for r in rows]
    values = back.values()
    assert values["GL_DIM_N"].value == a.n and values["GL_DIM_N"].ptype == 6
    gains = [n for n in values if re.fullmatch(r"GL_(AD|BD|CD|DD|K|L|CI|KI|KAW)_\d+_\d+", n)]
    assert len(gains) > 40
    for name in gains:
        assert values[name].ptype == 9 and values[name].value == _matrix_value(a, name), name


def test_qgroundcontrols_own_file_reads_and_a_tiny_gain_survives_the_round_trip(tmp_path):
    path = tmp_path / "copter.params"
    path.write_text(QGC_FILE)
    pf = read_params_file(path)
    assert pf.law is None and pf.target == (1, 1)  # another stack: no gainlink law named
    v = pf.values()
    assert v["ATC_RAT_RLL_P"].value == float(np.float32(0.135)) and v["ATC_RAT_RLL_P"].ptype == 9
    assert (v["FS_GCS_ENABLE"].value, v["FS_GCS_ENABLE"].ptype, v["SERIAL0_BAUD"].value) == (0, 2, 115)
    for x in (1e-12, -3.3e-9, 6.02e23, 0.1, 2.0):  # QGroundControl's 18 decimals would lose the first two
        f32 = float(np.float32(x))
        assert float(np.float32(float(format_value(f32, 9)))) == f32, x


def test_the_diff_against_a_saved_file_is_the_diff_against_the_vehicle(mavlink_exe, pend, retuned, tmp_path):
    saved = tmp_path / "vehicle.params"
    fw, port = start_firmware(mavlink_exe, None)
    try:
        res = run_cli("mavlink", "params", "--connect", f"udpout:127.0.0.1:{port}", "--out", saved)
        assert res.code == 0, res.err
        live = run_cli("mavlink", "upload", retuned, "--connect", f"udpout:127.0.0.1:{port}", "--dry-run")
        assert live.code == 0, live.err
    finally:
        fw.stop()
    assert read_params_file(saved).law == "float32"  # the app's HEARTBEAT named it
    res = run_cli("mavlink", "upload", retuned, "--dry-run", "--against", saved)
    assert res.code == 0, res.err
    diff = [ln for ln in res.out.splitlines() if "->" in ln]
    assert diff == [ln for ln in live.out.splitlines() if "->" in ln] and len(diff) > 5
    n = len(diff)
    assert f"dry run against {saved}: {n} parameter(s) would change" in res.out
    assert f"dry run: {n} parameter(s) would change" in live.out


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ("1\t1\tGL_K_0_0\t1.5", "line 9: expected 5 fields"),
        ("1\t1\tGL_K_0_0\tfast\t9", "line 9: GL_K_0_0: value 'fast' is not a number"),
        ("1\t1\tGL_DIM_N\t4.5\t6", "line 9: GL_DIM_N: value '4.5' is not a whole number"),
        ("1\t1\tGL_K_0_0\t1.5\t42", "line 9: GL_K_0_0: type 42 is not a MAV_PARAM_TYPE"),
        ("1\t1\tA_NAME_OF_17_CHAR\t1\t9", "line 9: parameter id 'A_NAME_OF_17_CHAR' is not 1 to 16 characters"),
        ("1\t1\tACRO_BAL_PITCH\t1\t9", "line 10: ACRO_BAL_PITCH again (first on line 9)"),
    ],
)
def test_a_bad_params_file_is_one_line_naming_its_line_and_nothing_written(pend, tmp_path, line, words):
    path = tmp_path / "bad.params"
    header, body = QGC_FILE.split("# Vehicle-Id Component-Id Name Value Type\n")
    path.write_text(header + "# Vehicle-Id Component-Id Name Value Type\n" + line + "\n" + body)
    out = tmp_path / "out.params"
    assert_refused(("mavlink", "params", path, "--out", out), f"params file {path} {words}", tmp_path)
    assert_refused(("mavlink", "upload", pend, "--dry-run", "--against", path), words, tmp_path)


def test_against_needs_a_dry_run_and_params_one_source(pend, tmp_path):
    saved = tmp_path / "p.params"
    assert run_cli("mavlink", "params", pend, "--out", saved).code == 0
    assert_refused(("mavlink", "upload", pend, "--against", saved), "give --dry-run", tmp_path)
    assert_refused(("mavlink", "params"), "give a vehicle (--connect URL) or a file", tmp_path)
    assert_refused(("mavlink", "upload", pend), "give --connect URL", tmp_path)


def test_a_listing_into_a_closed_pipe_ends_quietly_with_141(pend):
    proc = subprocess.Popen([GAINLINK, "mavlink", "params", str(pend)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # as `| head -1` does once it has its line
    _, err = proc.communicate(timeout=60)
    assert (proc.returncode, err) == (141, b"")
