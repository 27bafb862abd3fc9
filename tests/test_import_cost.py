"""``gainlink hil run`` imports only what a run uses: no SciPy, python-control or matplotlib for a float32 artifact
with ``--no-plots`` (they cost most of the vcan VM's emulated CPU; see docs/design.md, "Imports cost what is used"),
while the curated ``gl.*`` names still come when asked for."""

from __future__ import annotations

import json
import subprocess
import sys

from support.hil import pendulum_scenario, udp_transport, write_scenario

HEAVY = (
    "scipy",
    "control",
    "slycot",
    "matplotlib",
    "dask",
    "clarabel",
    "scs",
    "flint",
    "gainlink.api",
    "gainlink.firmware.build",
)

#: Runs the command line in a fresh interpreter, then prints which heavy modules it had imported.
PROBE = (
    "import json, sys\n"
    "from gainlink.cli import main\n"
    "code = main(sys.argv[1:])\n"
    f"print(json.dumps({{'code': code, 'heavy': sorted(m for m in {HEAVY!r} if m in sys.modules)}}))\n"
)


def _probe(*argv: object, cwd) -> dict:
    res = subprocess.run(
        [sys.executable, "-c", PROBE, *map(str, argv)], capture_output=True, text=True, timeout=300, cwd=cwd
    )
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_hil_run_without_plots_imports_no_design_side(tmp_path, pend, can_firmware, cart_fmu):
    scenario = pendulum_scenario(
        gains=pend, fmu=cart_fmu, transport=udp_transport(fd=True), duration=0.2, firmware=str(can_firmware)
    )
    write_scenario(tmp_path / "s.toml", scenario)
    quiet = _probe("hil", "run", "s.toml", "--report", "r", "--no-progress", "--no-plots", cwd=tmp_path)
    assert quiet == {"code": 0, "heavy": []}
    assert (tmp_path / "r" / "report.json").is_file() and not list((tmp_path / "r").glob("*.png"))
    # (with plots, matplotlib is imported and the PNGs are written: tests/test_hil_bridge.py)


def test_the_curated_names_are_imported_on_first_use():
    code = (
        "import sys, gainlink as gl\n"
        "assert 'scipy' not in sys.modules and 'gainlink.api' not in sys.modules\n"
        "from gainlink import design, GainlinkError\n"
        "import gainlink.api, gainlink.errors\n"
        "assert design is gainlink.api.design and GainlinkError is gainlink.errors.GainlinkError\n"
        "assert gl.Artifact.__module__ == 'gainlink.shipping.artifact' and set(gl.__all__) <= set(dir(gl))\n"
        "from gainlink.synthesis import synthesize_lq\n"
        "import gainlink.synthesis.pipeline as p\n"
        "assert synthesize_lq is p.synthesize_lq\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
