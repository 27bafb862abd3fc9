"""Type-check gainlink with mypy: the modules named in pyproject.toml's ``[tool.mypy] modules``, strictly.

    .venv/bin/python scripts/typecheck.py [more mypy arguments]

mypy finds packages by folder name and cannot follow the editable install's import hook, and gainlink's folders
are not named like its packages (``runtime/`` is ``gainlink``, ``hil/`` is ``gainlink.hil``). So the script lays
out the package's shape as a tree of symlinks under ``.cache/mypy/src`` (``gainlink/*`` -> ``runtime/*``,
``gainlink/hil`` -> ``hil/``), runs mypy on it, and prints mypy's messages with the checkout's paths.
Exit status: mypy's.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from gainlink.fileio import exclusive_lock

ROOT = Path(__file__).resolve().parents[1]
WORK = ROOT / ".cache" / "mypy"
#: the package's folders: import name -> folder of the checkout
PACKAGES = {"gainlink": ROOT / "runtime", "gainlink/hil": ROOT / "hil"}


def link_tree(src: Path) -> None:
    """Make ``src/gainlink`` a folder whose entries link to ``runtime/``'s, with ``hil`` linking to ``hil/``."""
    pkg = src / "gainlink"
    pkg.mkdir(parents=True, exist_ok=True)
    wanted = {p.name: p for p in PACKAGES["gainlink"].iterdir() if p.name != "__pycache__"}
    wanted["hil"] = PACKAGES["gainlink/hil"]
    for entry in pkg.iterdir():
        if entry.name not in wanted or os.readlink(entry) != str(wanted[entry.name]):
            entry.unlink()
    for name, target in wanted.items():
        if not (pkg / name).is_symlink():
            (pkg / name).symlink_to(target)


def checkout_paths(text: str) -> str:
    """mypy's messages with ``gainlink/hil/...`` and ``gainlink/...`` turned into ``hil/...`` and ``runtime/...``."""
    text = re.sub(r"^gainlink/hil/", "hil/", text, flags=re.M)
    return re.sub(r"^gainlink/", "runtime/", text, flags=re.M)


def main(argv: list[str]) -> int:
    src = WORK / "src"
    with exclusive_lock(WORK / ".lock"):  # one run at a time shares the tree and mypy's cache
        link_tree(src)
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "mypy",
                "--config-file",
                str(ROOT / "pyproject.toml"),
                "--cache-dir",
                str(WORK / "cache"),
                *argv,
            ],
            cwd=src,
            env={**os.environ, "MYPYPATH": str(src)},
            capture_output=True,
            text=True,
        )
    sys.stdout.write(checkout_paths(proc.stdout))
    sys.stderr.write(checkout_paths(proc.stderr))
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
