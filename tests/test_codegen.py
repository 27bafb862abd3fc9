"""``gainlink export``: generated C that names its artifact, is reproducible and holds the artifact's numbers."""

from __future__ import annotations

import json
import re
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from gainlink.shipping.artifact import render

GAINLINK = str(Path(sys.executable).with_name("gainlink"))
FLOAT = r"-?\d+(?:\.\d*)?(?:e[-+]?\d+)?f"


def export(art: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([GAINLINK, "export", str(art), "--out", str(out)], capture_output=True, text=True)


@pytest.mark.parametrize("name", ["pendulum", "quadrotor_lateral", "wood_berry"])
def test_export_is_reproducible_and_names_the_artifact(example_artifacts, tmp_path, name):
    art = example_artifacts[name]
    data = json.loads(art.read_text())
    assert export(art, tmp_path / "a").returncode == 0
    assert export(art, tmp_path / "b").returncode == 0
    files = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert files == ["gl_gains.c", "gl_gains.h", "gl_gains_layout.h", "gl_step.h"]
    for f in files:
        text = (tmp_path / "a" / f).read_text("utf-8")
        assert text == (tmp_path / "b" / f).read_text("utf-8"), f"{f} differs between two exports"
        assert text.startswith(f"/* DO NOT EDIT — generated from {data['name']} sha256:{data['sha256']}")
        assert not re.search(r"\d{4}-\d{2}-\d{2}|\d{2}:\d{2}:\d{2}", text), f"{f} holds a date or time"
        assert str(tmp_path) not in text
    header = (tmp_path / "a" / "gl_gains.h").read_text()
    for key in "nmpq":
        assert f"#define GL_{key.upper()} {data[key]}\n" in header


def test_generated_numbers_are_the_artifacts_float32_values(example_artifacts, tmp_path):
    art = example_artifacts["wood_berry"]
    data = json.loads(art.read_text())
    assert export(art, tmp_path).returncode == 0
    src = (tmp_path / "gl_gains.c").read_text()
    # designated initialisers for every field, rows as [i] = {...}
    for field in (
        "Ts",
        "Ad",
        "Bd",
        "Cd",
        "Dd",
        "K",
        "L",
        "M",
        "Ci",
        "Ki",
        "Kaw",
        "u_min",
        "u_max",
        "xh0",
        "z0",
        "u_op",
        "y_op",
        "crc32",
    ):
        assert re.search(rf"^    \.{field} = ", src, re.M), f"no designated initialiser for .{field}"
    assert "[1] = {" in src
    for key in ("Ad", "K", "L", "Ki"):
        block = re.search(rf"\.{key} = \{{\n(.*?)\n    \}},", src, re.S).group(1)
        rows = [re.findall(FLOAT, line) for line in block.splitlines()]
        got = np.array([[np.float32(v[:-1]) for v in row] for row in rows], dtype=np.float32)
        want = np.array(data[key], dtype=np.float64).astype(np.float32)
        assert np.array_equal(got, want), f"{key}: a literal does not read back to the artifact's float32 value"
    # the recorded CRC-32 is zlib's over the little-endian payload, recomputed here from the JSON
    n, m, p, q = (data[k] for k in "nmpq")
    qa = max(q, 1)

    def padded(key, shape):
        out = np.zeros(shape, dtype="<f4")
        if key in data:
            a = np.array(data[key], dtype=np.float64)
            out[tuple(slice(0, s) for s in a.shape)] = a
        return out

    payload = struct.pack(
        "<6I",
        n,
        m,
        p,
        q,
        {"predictor": 0, "current": 1}[data["observer_form"]],
        {"none": 0, "clamp": 1, "backcalc": 2}[data["anti_windup"]],
    )
    payload += np.array([data["Ts"]], dtype="<f4").tobytes()
    for key, shape in (
        ("Ad", (n, n)),
        ("Bd", (n, m)),
        ("Cd", (p, n)),
        ("Dd", (p, m)),
        ("K", (m, n)),
        ("L", (n, p)),
        ("M", (n, p)),
        ("Ci", (qa, p)),
        ("Ki", (m, qa)),
        ("Kaw", (qa, m)),
        ("u_min", (m,)),
        ("u_max", (m,)),
        ("xh0", (n,)),
        ("z0", (qa,)),
        ("u_op", (m,)),
        ("y_op", (p,)),
    ):
        payload += padded(key, shape).tobytes()
    crc = zlib.crc32(payload)
    assert f".crc32 = 0x{crc:08X}u," in src
    assert f"#define GL_GAINS_CRC32 0x{crc:08X}u" in (tmp_path / "gl_gains.h").read_text()


def test_export_rejects_a_tampered_artifact_without_writing(example_artifacts, tmp_path):
    data = json.loads(example_artifacts["pendulum"].read_text())
    data["K"][0][0] += 1.0
    bad = tmp_path / "gains.json"
    bad.write_text(render(data))
    out = tmp_path / "out"
    proc = export(bad, out)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "sha256" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists() or not any(out.iterdir())


def test_generated_code_compiles_standalone_with_strict_flags(example_artifacts, tmp_path):
    """The gains source compiles on its own against the library header with the house flags."""
    assert export(example_artifacts["quadrotor_lateral"], tmp_path).returncode == 0
    include = Path(__file__).resolve().parents[1] / "firmware" / "include"
    proc = subprocess.run(
        [
            "cc",
            "-std=c11",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-c",
            "-o",
            str(tmp_path / "g.o"),
            "-I",
            str(include),
            "-I",
            str(tmp_path),
            str(tmp_path / "gl_gains.c"),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
