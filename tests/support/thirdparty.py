"""FMUs the project did not write, fetched at test time from PyPI into the ignored cache (never committed).

``gemseo-fmu`` 3.1.1 ships OpenModelica 1.19 exports for Linux; ``Mass_Damper.fmu`` is a mass on a spring
and a damper pushed by a force: input ``f`` (N), output ``y`` (m, start value -0.5), FMI 2.0 Model Exchange and
Co-Simulation. The wheel and the FMU are pinned by sha256.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from gainlink.fileio import atomic_write_bytes, exclusive_lock
from gainlink.hil.paths import cache_dir

WHEEL = "gemseo_fmu-3.1.1-py3-none-any.whl"
WHEEL_SHA256 = "940b0200fe13cd00cc2b0a318bc4f1c8ddc147357fe3fe7ef8e53ae6ace5728e"
FMUS = {  # member of the wheel -> sha256 (ramp.fmu: an output and no input)
    "Mass_Damper.fmu": "319a1417576bc63ca148e688dd25cc1e834e0c112172405fc0f18132073f136e",
    "ramp.fmu": "9879b148929a6e353857a4a8816ffa20fd3ba970e96ef2117c1d1facf01ab663",
}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def gemseo_fmu(name: str) -> Path:
    """``name`` (e.g. ``Mass_Damper.fmu``) from the pinned gemseo-fmu wheel, downloaded once with pip.

    Safe when several test processes ask at once: one downloads and extracts under a file lock, into temporary
    names renamed when complete; the others wait and find the result.
    """
    folder = cache_dir("thirdparty")
    fmu = folder / name
    expected = FMUS[name]
    if fmu.exists() and _sha256(fmu) == expected:
        return fmu
    with exclusive_lock(folder / ".lock"):
        if not (fmu.exists() and _sha256(fmu) == expected):
            _extract(_wheel(folder), name, expected, fmu)
    return fmu


def _wheel(folder: Path) -> Path:
    """The pinned wheel in ``folder``, downloaded with pip unless it is already there."""
    wheel = folder / WHEEL
    if wheel.exists() and _sha256(wheel) == WHEEL_SHA256:
        return wheel
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        subprocess.run(
            [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "gemseo-fmu==3.1.1"]
            + ["-d", tmp, "-q"],
            check=True,
            timeout=300,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        digest = _sha256(Path(tmp) / WHEEL)
        if digest != WHEEL_SHA256:
            raise RuntimeError(f"{WHEEL}: sha256 {digest} is not the pinned {WHEEL_SHA256}")
        os.replace(Path(tmp) / WHEEL, wheel)
    return wheel


def _extract(wheel: Path, name: str, expected: str, fmu: Path) -> None:
    with zipfile.ZipFile(wheel) as z:
        data = z.read(f"gemseo_fmu/problems/fmu_files/linux/{name}")
    if hashlib.sha256(data).hexdigest() != expected:
        raise RuntimeError(f"{name} in {wheel} does not have the pinned sha256 {expected}")
    atomic_write_bytes(fmu, data)


#: The design tables a spec linearised from Mass_Damper.fmu takes (``linearize --template``).
TEMPLATE = """
[controller]
method = "lqr"
Q_diag = [100.0, 0.0]
R_diag = [1.0e-4]

[integral]
outputs = ["y"]
Q_diag = [1.0e6]

[observer]
method = "kalman"
form = "predictor"
W_diag = [1.0e-4, 1.0e-2]
V_diag = [1.0e-8]

[limits]
u_min = [-2000.0]
u_max = [2000.0]
anti_windup = "backcalc"
"""
