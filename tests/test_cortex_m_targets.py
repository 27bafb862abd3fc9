"""Every Cortex-M target (M0, M3, M4, M7, M33, M55) on its QEMU board: bit for bit with the host, the cost
of a step with its callees, and the command line's targets and boards.

The float32 law's arithmetic is IEEE single with one rounding per multiply-add on every target: the FPU's
vfma.f32 where there is one, gl_fmaf (firmware/src/gl_fmaf.c) on the soft-float M0 and M3. So every image
equals the host library (libm fmaf) bit for bit; gl_fmaf itself is checked against the C library's fmaf on
the host. One quick replay per target here; every example on every target, with PIL, is the matrix
(tests/test_target_matrix.py, `make test-matrix`).
"""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest
from gainlink.engines import qemu as qemu_engine
from gainlink.engines.native import NativeLoop
from gainlink.firmware import qemu as fwqemu
from gainlink.firmware.build import firmware_dir, replay_image
from gainlink.firmware.cost import count_step_instructions
from gainlink.firmware.targets import BOARDS, CORTEX_M_TARGETS, TARGETS
from gainlink.hil.loop.pil import make_plant, run_pil
from gainlink.shipping.artifact import load
from support.cli import assert_refused, run_cli
from support.designs import golden_examples

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("u", "sat", "xh", "z", "fault")


@pytest.fixture(scope="module", autouse=True)
def _quiet_design_warnings():
    logging.disable(logging.WARNING)
    yield
    logging.disable(logging.NOTSET)


@pytest.fixture(scope="module")
def pendulum():
    return golden_examples()[0]


def assert_bit_identical(a: dict, b: dict, label: str) -> None:
    for key in KEYS:
        assert a[key].shape == b[key].shape, f"{label}: {key} shape"
        assert np.array_equal(a[key].view(np.uint8), b[key].view(np.uint8)), f"{label}: {key} differs in its bits"


# --- gl_fmaf, the soft-float targets' multiply-add -----------------------------------------------------------


def _build_fmaf_check(out: Path, *defines: str) -> Path:
    """firmware/tools/gl_fmaf_check.c built for the host with gl_fmaf.c (the same C the M0 and M3 run)."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.fail("no host C compiler")
    src = firmware_dir()
    cmd = [cc, "-O2", "-std=c11", "-Wall", "-Wextra", "-Werror", "-ffp-contract=off", f"-I{src / 'src'}", *defines]
    cmd += [str(src / "src" / "gl_fmaf.c"), str(src / "tools" / "gl_fmaf_check.c"), "-lm", "-o", str(out)]
    subprocess.run(cmd, check=True)
    return out


@pytest.fixture(scope="module")
def fmaf_check(tmp_path_factory) -> Path:
    return _build_fmaf_check(tmp_path_factory.mktemp("fmaf") / "gl_fmaf_check")


@pytest.mark.parametrize("multiply", ["64-bit", "16-bit halves (ARMv6-M)"])
def test_gl_fmaf_rounds_once_like_the_c_library(tmp_path, multiply):
    """7 x 400k triples per seed (ties, subnormals, overflow, cancellation, double-rounding traps) against the
    C library's fmaf (glibc: correctly rounded), bit for bit; with both forms of the significand product."""
    defines = ["-DGL_FMAF_SPLIT_MULTIPLY"] if multiply.startswith("16") else []
    exe = _build_fmaf_check(tmp_path / "gl_fmaf_check", *defines)
    for seed in (1, 2):
        proc = subprocess.run([str(exe), "400000", str(seed)], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stdout
        assert proc.stdout.strip().endswith("cases=2800000 mismatches=0")


def test_newlib_formula_is_caught_by_the_same_check(fmaf_check):
    """(float)((double)a*b + c), newlib's fmaf, rounds twice: the check finds it wrong (so it can fail).

    A replay cannot show this: the double-rounded result differs only when the double sum lands exactly on
    a float midpoint (about 2^-29 of multiply-adds on smooth data; the pendulum's 600 golden steps come
    out identical with newlib's fmaf). The check's trap class puts a product on a midpoint on purpose."""
    proc = subprocess.run([str(fmaf_check), "100000", "1", "double"], capture_output=True, text=True)
    assert proc.returncode == 1
    mismatches = int(proc.stdout.strip().rsplit("mismatches=", 1)[1])
    assert mismatches > 1000, proc.stdout


# --- every target, bit for bit ------------------------------------------------------------------------------


@pytest.mark.parametrize("target", CORTEX_M_TARGETS)
def test_every_target_equals_the_host_bit_for_bit(pendulum, target):
    Y = pendulum.Y.copy()
    Y[17, 0] = np.nan  # a refused sample travels through both
    host = NativeLoop(pendulum.artifact).run_raw(Y, pendulum.R)
    image = qemu_engine.run_raw(pendulum.artifact, Y, pendulum.R, target=target)
    assert_bit_identical(host, image, target)
    assert image["fault"].sum() == 1 and image["sat"].any(), "the samples take the fault and saturated paths"


@pytest.mark.parametrize("board", list(BOARDS))
def test_uart_banner_and_one_step_on_every_board(pendulum, board):
    """Without an input file each image prints its banner and one step's command bits on its console UART."""
    a = pendulum.artifact
    elf = replay_image(a, target=BOARDS[board].core, board=board)
    with tempfile.TemporaryDirectory() as tmp:
        res = fwqemu.run_image(elf, board=board, cwd=Path(tmp), timeout_s=10)
    assert res.returncode == 0, res.meaning
    lines = res.uart.splitlines()
    assert lines[0] == f"gainlink {a.name} {board} sha256:{a.sha256} law=float32 variant=unrolled wire=4"
    host = NativeLoop(a).step(np.full(a.p, 0.5), np.zeros(a.q))
    bits = " ".join(f"u=0x{int(v):08X}" for v in host.u.view(np.uint32))
    assert lines[1] == f"step 0x{host.status & 0xFFFFFFFF:08X} {bits}"


# --- cost of a step, callees included ----------------------------------------------------------------------


@pytest.mark.parametrize("target", CORTEX_M_TARGETS)
def test_step_cost_counts_every_instruction_of_the_call(pendulum, target):
    a, N = pendulum.artifact, 200
    board = TARGETS[target].default_board
    elf = replay_image(a, target=target, board=board)
    cost = count_step_instructions(elf, a, Y=pendulum.Y[:N], R=pendulum.R[:N], board=board)
    assert cost.calls == N, "one count per gl_loop_step call"
    assert cost.cheapest * N <= cost.instructions <= cost.dearest * N
    assert cost == count_step_instructions(elf, a, Y=pendulum.Y[:N], R=pendulum.R[:N], board=board), "exact"
    if TARGETS[target].hardware_fma:
        # the step calls nothing here: the call count equals the count inside its own symbol, a different method
        assert cost.instructions == cost.own
        assert cost.per_step <= 110
    else:
        # soft float: the arithmetic lives in gl_fmaf and libgcc, outside the step's symbol
        assert cost.instructions > 10 * cost.own


# --- the command line: targets and boards ------------------------------------------------------------------


def test_firmware_build_for_a_soft_float_target_writes_its_image(pend, tmp_path):
    out = tmp_path / "fw"
    res = run_cli("firmware", "build", pend, "--target", "cortex-m0", "--out", out)
    assert res.code == 0, res.err
    assert "on microbit" in res.out
    for ext in ("elf", "bin", "hex", "map"):
        assert (out / f"gainlink_pendulum.{ext}").stat().st_size > 0
    report = json.loads((out / "gainlink_pendulum.size.json").read_text())
    manifest = json.loads((out / "firmware.json").read_text())
    assert (manifest["target"], manifest["board"], report["board"]) == ("cortex-m0", "microbit", "microbit")
    assert report["ram_bytes"] <= 16 * 1024, "fits the micro:bit's 16 KiB"
    assert (out / "gainlink_pendulum.bin").stat().st_size == report["flash_bytes"]
    a = load(pend)
    rec = fwqemu.replay(out / "gainlink_pendulum.elf", a, board="microbit", Y=[[0.1, 0.0]], R=[[0.2]])
    assert rec["status"][0] >= 0
    dry = run_cli("firmware", "flash", out, "--probe", "pyocd", "--dry-run")
    assert dry.code == 0 and dry.out.startswith("pyocd flash --target nrf51 --format hex "), dry.out


def test_flashing_an_fpga_board_image_names_its_loader_in_one_line(pend, tmp_path):
    out = tmp_path / "fw"
    assert run_cli("firmware", "build", pend, "--target", "cortex-m33", "--out", out).code == 0
    res = assert_refused(("firmware", "flash", out, "--probe", "pyocd", "--dry-run"), "mps2-an505", tmp_path)
    assert ".bin" in res.err, res.err


@pytest.mark.parametrize(
    "argv,word",
    [
        (
            ["firmware", "build", "{art}", "--target", "cortex-m0", "--board", "mps2-an386", "--out", "{out}"],
            "cortex-m4",
        ),
        (["firmware", "build", "{art}", "--target", "cortex-m9", "--out", "{out}"], "cortex-m9"),
        (["firmware", "build", "{art}", "--target", "cortex-m7", "--board", "nope", "--out", "{out}"], "nope"),
        (["firmware", "build", "{art}", "--target", "host", "--board", "microbit", "--out", "{out}"], "microbit"),
        (
            ["pil", "run", "{art}", "--steps", "5", "--target", "cortex-m3", "--board", "microbit", "--out", "{out}"],
            "microbit",
        ),
        (["pil", "run", "{art}", "--steps", "5", "--target", "host", "--out", "{out}"], "host"),
        (["pil", "run", "{art}", "--steps", "5", "--board", "mps9", "--out", "{out}"], "mps9"),
        (["replay", "{art}", "--input", "{csv}", "--output", "{out}", "--engine", "qemu", "--target", "m4"], "m4"),
        # an image's targets only: the host is not among them
        (
            ["replay", "{art}", "--input", "{csv}", "--output", "{out}", "--engine", "qemu", "--target", "cortex-m9"],
            "unknown target 'cortex-m9' (did you mean 'cortex-m7'?) (choose from cortex-m0, cortex-m3,",
        ),
        (["replay", "{art}", "--input", "{csv}", "--output", "{out}", "--engine", "qemu", "--board", "x"], "x"),
        (["replay", "{art}", "--input", "{csv}", "--output", "{out}", "--target", "cortex-m0"], "--engine qemu"),
        (
            [
                "replay",
                "{art}",
                "--input",
                "{csv}",
                "--output",
                "{out}",
                "--engine",
                "qemu",
                "--target",
                "cortex-m55",
                "--board",
                "mps2-an505",
            ],
            "cortex-m33",
        ),
        (["firmware", "run", "{art}", "--target", "cortex-m0", "--mavlink", "tcp:127.0.0.1:1"], "no bus node"),
    ],
)
def test_unknown_or_mismatched_target_or_board_is_one_line_exit_2_and_nothing_written(pend, tmp_path, argv, word):
    csv = tmp_path / "in.csv"
    csv.write_text("y0,y1,r0\n0.1,0.0,0.2\n")
    out = tmp_path / "out"
    assert_refused([a.format(art=pend, out=out, csv=csv) for a in argv], word, tmp_path)


def test_replay_cli_on_the_m0_matches_native_and_passes_the_one_step_check(pend, tmp_path, pendulum):
    rows = ["y0,y1,r0"] + [
        ",".join(repr(float(v)) for v in np.concatenate([pendulum.Y[k], pendulum.R[k]])) for k in range(300)
    ]
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    outs = {}
    for engine, extra in (("native", []), ("qemu", ["--target", "cortex-m0"])):
        res = run_cli(
            "replay",
            pend,
            "--input",
            tmp_path / "in.csv",
            "--output",
            tmp_path / f"{engine}.csv",
            "--engine",
            engine,
            *extra,
        )
        assert res.code == 0, res.err
        outs[engine] = (tmp_path / f"{engine}.csv").read_text()
    assert "through qemu (cortex-m0)" in res.out
    assert outs["native"] == outs["qemu"]
    res = run_cli(
        "replay",
        pend,
        "--input",
        tmp_path / "in.csv",
        "--output",
        tmp_path / "again.csv",
        "--engine",
        "qemu",
        "--board",
        "microbit",
        "--compare",
        tmp_path / "native.csv",
    )
    assert res.code == 0, res.err
    assert res.out.count("one-step check") == 2 and "max |du| = 0 " in res.out


# --- processor in the loop on a soft-float and a Helium core ------------------------------------------------


@pytest.mark.parametrize("target", ["cortex-m0", "cortex-m55"])
def test_pil_closes_the_loop_on_other_cores(pend, target):
    a = load(pend)
    res = run_pil(
        a,
        plant=make_plant("artifact", artifact=a),
        steps=1500,
        reference=[0.3],
        target=target,
        twin=make_plant("artifact", artifact=a),
    )
    assert not np.any(res.flags & 0x01)  # no sample refused (the fault flag)
    assert 0 < res.comparison.worst_du_rel <= 1e-4, "float32 firmware against its float64 twin"
    assert abs(res.y[-1, 0] - 0.3) < 0.02, "the cart reaches the reference"


def test_pil_cli_with_a_board_alone_runs_that_boards_core(pend, tmp_path):
    res = run_cli("pil", "run", pend, "--board", "mps2-an500", "--steps", "50", "--out", tmp_path / "pil")
    assert res.code == 0, res.err
    summary = json.loads((tmp_path / "pil" / "pil.json").read_text())
    assert (summary["target"], summary["board"], summary["steps"]) == ("cortex-m7", "mps2-an500", 50)
    # a one-screen summary, as hil run prints one (the JSON with --json), from the numbers pil.json holds
    lines = res.out.splitlines()
    assert lines[0] == "PIL run pendulum on mps2-an500 (cortex-m7, QEMU), plant artifact: 50 steps"
    assert f"p50 {summary['round_trip_us_p50']:.4g} us" in lines[2] and "saturated 0 of 50 steps" in lines[3]
    tw = summary["twin"]["inputs"]["F"]
    assert f"max |u - u_twin|: F {tw['max_du']:.4g} N ({tw['max_du_rel']:.3g} of span)" in res.out
    x, theta = summary["final_output"]
    assert f"final outputs: x {x:.4g} m, theta {theta:.4g} rad" in res.out and len(lines) < 20


# --- the image as a bus node on another core's board --------------------------------------------------------


@pytest.mark.slow
def test_mavlink_hil_through_the_m33_images_uart_equals_the_host_app(pend):
    """The AN505 (Secure image, its own UART lines and timer): the same closed loop as the host app, bit for bit."""
    from gainlink.hil.loop.bridge import run_scenario
    from support.net import tcp_port, udp_port
    from support.uart import assert_same_closed_loop, scenario

    host = run_scenario(scenario(pend, {"kind": "mavlink", "port": udp_port()}, controller="firmware"))
    url = f"tcp:127.0.0.1:{tcp_port()}"
    image = run_scenario(scenario(pend, {"kind": "mavlink", "url": url}, controller="qemu", board="mps2-an505"))
    assert_same_closed_loop(image, host)
    assert image.info["controller"]["ready"].startswith("gainlink pendulum mps2-an505 ")
