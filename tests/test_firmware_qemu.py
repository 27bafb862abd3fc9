"""The Cortex-M4F image under qemu-system-arm: bit for bit against the host build, on both boards.

Both builds use -ffp-contract=off and explicit fused multiply-adds (fmaf / vfma.f32), so every float32
result of the image must equal the host library's exactly; comparisons here are on the raw bits.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from gainlink.engines import qemu as qemu_engine
from gainlink.engines.native import NativeLoop
from gainlink.firmware import qemu as fwqemu
from gainlink.firmware.build import build, replay_image
from gainlink.laws.lq.golden import random_cases
from gainlink.shipping.artifact import render
from support.cli import assert_refused
from support.designs import golden_examples

KEYS = ("u", "sat", "xh", "z", "fault")
GAINLINK = str(Path(sys.executable).with_name("gainlink"))  # the console script, run as a real process


pytestmark = pytest.mark.usefixtures("quiet_design_warnings")


def assert_bit_identical(a: dict, b: dict, label: str) -> None:
    for key in KEYS:
        assert a[key].shape == b[key].shape, f"{label}: {key} shape"
        assert np.array_equal(a[key].view(np.uint8), b[key].view(np.uint8)), f"{label}: {key} differs in its bits"


@pytest.mark.parametrize("board", ["mps2-an386", "netduinoplus2"])
def test_examples_bit_identical_to_host_on_both_boards(board):
    for case in golden_examples():
        Y = case.Y.copy()
        Y[17, 0] = np.nan  # a refused sample travels through both
        host = NativeLoop(case.artifact).run_raw(Y, case.R)
        target = qemu_engine.run_raw(case.artifact, Y, case.R, board=board)
        assert_bit_identical(host, target, f"{case.label}/{board}")
        assert target["fault"].sum() == 1


RANDOM_DESIGNS = 12  # conftest's random_designs; the matrix runs the other 18 of golden.random_cases(30)


def assert_image_equals_host(case) -> None:
    """The M4F image replays the case bit for bit as the host library, a refused sample (the safe command:
    u_op clamped into the limits) included."""
    Y = case.Y.copy()
    Y[11, 0] = np.nan
    host = NativeLoop(case.artifact).run_raw(Y, case.R)
    target = qemu_engine.run_raw(case.artifact, Y, case.R)
    assert_bit_identical(host, target, case.label)
    assert np.array_equal(target["u"][11], case.artifact.safe_command.astype(np.float32)), case.label


@pytest.mark.parametrize("index", range(RANDOM_DESIGNS))  # one test each: the workers build them in parallel
def test_random_design_bit_identical_to_host(random_designs, index):
    assert_image_equals_host(random_designs[index])


@pytest.mark.matrix
@pytest.mark.parametrize("index", range(RANDOM_DESIGNS, 30))
def test_more_random_designs_bit_identical_to_host(index):
    assert_image_equals_host(random_cases(30)[index])


@pytest.fixture(scope="module")
def pendulum():
    return golden_examples()[0]


def test_watchdog_in_the_image(pendulum):
    a = pendulum.artifact
    elf = replay_image(a, target="cortex-m4", board="mps2-an386")
    tags = np.zeros(30, dtype=np.uint32)
    tags[10:16] = fwqemu.TAG_IDLE  # six periods without a measurement, watchdog at 4
    rec = fwqemu.replay(
        elf,
        a,
        board="mps2-an386",
        Y=pendulum.Y[:30],
        R=pendulum.R[:30],
        tags=tags,
        watchdog_periods=4,
    )
    status = rec["status"].tolist()
    assert status[10:13] == [0, 0, 0] and status[13:16] == [-6, -6, -6]
    assert np.all(rec["u"][10:13] == rec["u"][9]), "holds the last command"
    assert np.all(rec["u"][13:16] == np.float32(np.clip(0.0, a.u_min, a.u_max)))
    assert status[16] in (0, 1), "a measurement re-arms it"


def test_fpu_left_disabled_is_caught_by_the_startup_self_test(pendulum):
    a = pendulum.artifact
    elf = build(a, target="cortex-m4", options={"GL_SKIP_FPU_ENABLE": "ON", "GL_IMAGE_SERVE": "OFF"}).files["elf"]
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "gl_in.bin").write_bytes(fwqemu.encode_input(a, pendulum.Y[:5], pendulum.R[:5]))
        res = fwqemu.run_image(elf, board="mps2-an386", cwd=Path(tmp), timeout_s=10)
    assert res.returncode == fwqemu.EXIT_FPU, f"expected the FPU self-test exit, got {res.meaning}"
    good = replay_image(a, target="cortex-m4", board="mps2-an386")
    with tempfile.TemporaryDirectory() as tmp:
        assert fwqemu.run_image(good, board="mps2-an386", cwd=Path(tmp), timeout_s=10).returncode == 0


@pytest.mark.parametrize("board", ["mps2-an386", "netduinoplus2"])
def test_uart_smoke(pendulum, board):
    """Without an input file the image prints its banner and one step's command bits on the UART."""
    a = pendulum.artifact
    elf = replay_image(a, target="cortex-m4", board=board)
    with tempfile.TemporaryDirectory() as tmp:
        res = fwqemu.run_image(elf, board=board, cwd=Path(tmp), timeout_s=10)
    assert res.returncode == 0, res.meaning
    lines = res.uart.splitlines()
    assert lines[0] == f"gainlink {a.name} {board} sha256:{a.sha256} law=float32 variant=unrolled wire=4"
    host = NativeLoop(a).step(np.full(a.p, 0.5), np.zeros(a.q))
    bits = " ".join(f"u=0x{int(v):08X}" for v in host.u.view(np.uint32))
    assert lines[1] == f"step 0x{host.status & 0xFFFFFFFF:08X} {bits}"


def test_cli_firmware_build_writes_images_and_size_report(tmp_path, pendulum):
    art = tmp_path / "gains.json"
    art.write_text(render(pendulum.artifact.data))
    out = tmp_path / "fw"
    for board in ("mps2-an386", "netduinoplus2"):
        proc = subprocess.run(
            [
                GAINLINK,
                "firmware",
                "build",
                str(art),
                "--target",
                "cortex-m4",
                "--board",
                board,
                "--out",
                str(out / board),
            ],
            capture_output=True,
            text=True,
        )
        assert proc.returncode == 0, proc.stderr
        d = out / board
        for ext in ("elf", "bin", "hex", "map"):
            assert (d / f"gainlink_pendulum.{ext}").stat().st_size > 0
        report = json.loads((d / "gainlink_pendulum.size.json").read_text())
        names = {s["name"]: s for s in report["sections"]}
        assert names[".text"]["flash"] and names[".bss"]["ram"] and not names[".bss"]["flash"]
        loaded = [s for s in report["sections"] if s["flash"] and s["size"]]
        gaps = report["flash_bytes"] - sum(s["size"] for s in loaded)
        assert 0 <= gaps < 8 * len(loaded), "the sections, and alignment gaps between them"
        assert report["symbols"]["gl_gains_default"]["size"] > 0
        bin_size = (d / "gainlink_pendulum.bin").stat().st_size
        assert bin_size == report["flash_bytes"], "the .bin holds exactly the flash sections"
        # the ELF the command wrote boots on its board and replays the golden samples bit for bit like the host
        a = pendulum.artifact
        rec = fwqemu.replay(d / "gainlink_pendulum.elf", a, board=board, Y=pendulum.Y, R=pendulum.R)
        host = NativeLoop(a).run_raw(pendulum.Y, pendulum.R)
        assert np.array_equal(rec["u"].view(np.uint32), host["u"].view(np.uint32))
        assert np.array_equal(rec["xh"].view(np.uint32), host["xh"].view(np.uint32))
    dry = subprocess.run(
        [GAINLINK, "firmware", "flash", str(out / "netduinoplus2"), "--probe", "openocd", "--dry-run"],
        capture_output=True,
        text=True,
    )
    assert dry.returncode == 0
    assert dry.stdout.strip().startswith("openocd -f interface/stlink.cfg -f target/stm32f4x.cfg -c 'program ")
    assert str((out / "netduinoplus2" / "gainlink_pendulum.elf").resolve()) in dry.stdout
    argv = [GAINLINK, "firmware", "flash", tmp_path, "--probe", "pyocd", "--dry-run"]
    assert_refused(argv, "firmware.json", tmp_path, process=True)


def test_replay_cli_with_qemu_engine_matches_native(tmp_path, pendulum):
    a = pendulum.artifact
    art = tmp_path / "gains.json"
    art.write_text(render(a.data))
    rows = ["y0,y1,r0"] + [
        ",".join(repr(float(v)) for v in np.concatenate([pendulum.Y[k], pendulum.R[k]])) for k in range(300)
    ]
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    outs = {}
    for engine in ("native", "qemu"):
        proc = subprocess.run(
            [
                GAINLINK,
                "replay",
                str(art),
                "--input",
                str(tmp_path / "in.csv"),
                "--output",
                str(tmp_path / f"{engine}.csv"),
                "--engine",
                engine,
            ],
            capture_output=True,
            text=True,
        )
        assert proc.returncode == 0, proc.stderr
        outs[engine] = (tmp_path / f"{engine}.csv").read_text()
    assert outs["native"] == outs["qemu"]


def test_gain_update_on_target_matches_host(pendulum):
    """Double-buffered update on the Cortex-M4F: a bad-checksum set is refused, a sealed set swaps in at the
    next step; the image and the host library agree bit for bit throughout."""
    import ctypes

    a = pendulum.artifact
    host = NativeLoop(a)
    bad = host.default_gains()
    bad.K[0][0] *= 1.2  # not re-sealed
    good = host.default_gains()
    good.K[0][0] *= 1.2
    good.crc32 = host.crc32(good)
    sets = [ctypes.string_at(ctypes.addressof(g), ctypes.sizeof(g)) for g in (bad, good)]
    N = 200
    tags = np.zeros(N, dtype=np.uint32)
    tags[[60, 120]] = fwqemu.TAG_STAGE
    rec = fwqemu.replay(
        replay_image(a, target="cortex-m4", board="mps2-an386"),
        a,
        board="mps2-an386",
        Y=pendulum.Y[:N],
        R=pendulum.R[:N],
        tags=tags,
        stage_sets=sets,
    )
    assert rec["status"][60] == -3 and rec["status"][120] == 0
    steps = tags == fwqemu.TAG_STEP
    # the host: same samples, same updates at the same points
    parts = [host.run_raw(pendulum.Y[:60], pendulum.R[:60])]
    assert host.stage(bad) == -3
    parts.append(host.run_raw(pendulum.Y[61:120], pendulum.R[61:120]))
    assert host.stage(good) == 0
    parts.append(host.run_raw(pendulum.Y[121:N], pendulum.R[121:N]))
    u = np.concatenate([p["u"] for p in parts])
    xh = np.concatenate([p["xh"] for p in parts])
    assert np.array_equal(rec["u"][steps].view(np.uint32), u.view(np.uint32))
    assert np.array_equal(rec["xh"][steps].view(np.uint32), xh.view(np.uint32))
    assert host.active_crc32() == good.crc32


def test_a_tree_configured_from_a_kept_compiler_detection_builds_the_same_firmware(pend, tmp_path, monkeypatch):
    """CMake's compiler detection is kept per configuration (gainlink.firmware.build.seed_root) and planted into the
    next tree of that configuration: that tree skips the detection, compiles with the same commands and links the
    same bytes (a Cortex-M4 image and the host library, each configured once without and once with the seed)."""
    from gainlink.firmware import build as build_mod
    from gainlink.shipping.artifact import load

    a = load(pend)
    monkeypatch.setattr(build_mod, "seed_root", lambda: tmp_path / "seeds")
    configures: list[list[str]] = []
    real_run = build_mod._run
    monkeypatch.setattr(
        build_mod, "_run", lambda cmd, **kw: (configures.append(cmd) if "-S" in cmd else None, real_run(cmd, **kw))[1]
    )
    # The trees sit as deep in the checkout's .cache as its own builds: ccache then serves their units (paths
    # relative to the checkout), and only the configure and the link are new.
    roots = [build_mod.cache_root().parent / f"seed-test-{os.getpid()}-{k}" for k in (1, 2)]
    try:
        _compare_seeded_builds(a, roots, configures)
    finally:
        for root in roots:
            shutil.rmtree(root, ignore_errors=True)


def _compare_seeded_builds(a, roots: list[Path], configures: list[list[str]]) -> None:
    for target, options, only, product in [
        ("cortex-m4", {"GL_IMAGE_SERVE": "OFF"}, None, "bin"),
        ("host", None, "gainlink_host", "shared"),
    ]:
        first, second = (build(a, target=target, options=options, only=only, build_root=root) for root in roots)
        seeded = ["-DCMAKE_PLATFORM_INFO_INITIALIZED=1" in cmd for cmd in configures[-2:]]
        assert seeded == [False, True], target
        commands = [
            subprocess.run(
                ["ninja", "-t", "commands"], cwd=r.build_dir, capture_output=True, text=True, check=True
            ).stdout.replace(str(r.build_dir.parent), "TREE")
            for r in (first, second)
        ]
        assert commands[0] == commands[1] and "-O2" in commands[0], target
        if target != "host":  # a shared object carries its build-id; an image is the same bytes
            assert first.files[product].read_bytes() == second.files[product].read_bytes(), target
