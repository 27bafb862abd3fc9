"""`design --numeric` and the replay engines of a fixed-point artifact: `model` (the bit-exact model), `native`
(the host C) and `qemu` (the Cortex-M image) write the same trace, byte for byte; the flag overrides the spec's
`[implementation] numeric`, and a fixed-point design without declared ranges is one line, exit 2, nothing written."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from gainlink.laws.fixed.firmware import replay_image, run_host
from gainlink.shipping.artifact import load
from support.cli import GOOD_SPEC, assert_refused, run_cli
from support.paths import EXAMPLES


@pytest.fixture(scope="module")
def pendulum_q31(tmp_path_factory) -> tuple:
    d = tmp_path_factory.mktemp("fixed-engines")
    res = run_cli("design", EXAMPLES / "pendulum.toml", "--out", d / "design", "--numeric", "q31")
    assert res.code == 0, res.err
    assert "fixed point q31" in res.out
    gains = d / "design" / "gains.json"
    sim = run_cli("simulate", gains, "--steps", "300", "--noise", "0.01", "--out", d / "in.csv")
    assert sim.code == 0, sim.err
    return d, gains, res.out


def test_design_prints_each_figure_with_the_words_the_artifact_records(pendulum_q31):
    """The headline's scope and the sharper figures' are printed in the words of checks.fixed_point.covers, and the
    printed headline is the recorded one (docs/design.md uses the same words)."""
    _, gains, out = pendulum_q31
    fp = json.loads(gains.read_text())["checks"]["fixed_point"]
    assert fp["covers"]["certified"] in out
    assert "beside it, covering less: from rest driven by references only" in out
    line = next(x for x in out.splitlines() if x.strip().startswith("F:") and "of the span" in x)
    assert f"{fp['error']['certified'][0]:.3g} = {fp['error']['fraction_of_span'][0]:.3g} of the span" in line


def test_numeric_flag_overrides_the_spec(pendulum_q31):
    _, gains, _ = pendulum_q31
    data = json.loads(gains.read_text())
    assert data["checks"]["fixed_point"]["numeric"] == "q31"


def test_fixed_point_without_ranges_is_one_line(tmp_path):
    spec = tmp_path / "servo.toml"
    spec.write_text(GOOD_SPEC)
    assert_refused(("design", spec, "--out", tmp_path / "out", "--numeric", "q31"), "range", tmp_path)


def test_replay_engines_of_a_fixed_point_artifact_agree_byte_for_byte(pendulum_q31):
    d, gains, _ = pendulum_q31
    outs = {}
    for engine, extra in (("model", ()), ("native", ()), ("qemu", ("--target", "cortex-m3"))):
        out = d / f"{engine}.csv"
        res = run_cli("replay", gains, "--input", d / "in.csv", "--output", out, "--engine", engine, *extra)
        assert res.code == 0, res.err
        outs[engine] = out.read_text()
    assert outs["model"] == outs["native"] == outs["qemu"]
    ref = d / "reference.csv"
    assert run_cli("replay", gains, "--input", d / "in.csv", "--output", ref).code == 0
    assert ref.read_text() != outs["native"]  # the float64 law is not what the fixed-point artifact runs


def test_firmware_build_ships_the_fixed_point_image(pendulum_q31, tmp_path):
    """`firmware build` of a fixed-point artifact writes one image, the integer law's (its manifest says so), and the
    written ELF is the one that runs (replayed from the output folder, equal to the host build)."""
    _, gains, _ = pendulum_q31
    res = run_cli("firmware", "build", gains, "--target", "cortex-m0", "--out", tmp_path / "fw")
    assert res.code == 0, res.err
    # The image built is printed with its size and the law it runs (the integer law: a float32 image was printed
    # before): flash as objcopy's .bin, RAM as binutils' size counts the sections at 0x20000000 and up.
    sizes = {line.split()[0]: line for line in res.out.splitlines() if line.startswith("gainlink_pendulum")}
    assert set(sizes) == {"gainlink_pendulum.elf"}, res.out
    for name, law in (("gainlink_pendulum.elf", "the q31 law: its UART's slcan node, replay and PIL"),):
        elf = tmp_path / "fw" / name
        table = subprocess.run(["arm-none-eabi-size", "-A", str(elf)], capture_output=True, text=True, check=True)
        ram = sum(
            int(f[1])
            for f in (ln.split() for ln in table.stdout.splitlines()[2:])
            if len(f) == 3 and f[2].isdigit() and int(f[2]) >= 0x20000000
        )
        flash = elf.with_suffix(".bin").stat().st_size
        assert f"{name} on microbit: flash {flash} B," in sizes[name] and f"({ram} B total)" in sizes[name], sizes[name]
        assert law in sizes[name], sizes[name]
    manifest = json.loads((tmp_path / "fw" / "firmware.json").read_text())
    assert manifest["law"] == "q31" and manifest["files"]["elf"] == "gainlink_pendulum.elf"
    assert (tmp_path / "fw" / "src" / "gl_fixed_gains.c").is_file()
    a = load(gains)
    Y = np.tile(np.array([[0.1, -0.02]], dtype=np.float32), (50, 1))
    R = np.full((50, 1), 0.3, dtype=np.float32)
    image = replay_image(tmp_path / "fw" / "gainlink_pendulum.elf", a, Y, R, board="microbit")
    assert np.array_equal(image.U, run_host(a, Y, R).U) and np.array_equal(image.XH, run_host(a, Y, R).XH)
