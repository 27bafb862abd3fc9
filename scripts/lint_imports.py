"""Run import-linter's contracts (pyproject.toml, ``[tool.importlinter]``) over all of gainlink.

gainlink's sources live in two folders mapped onto one package (``runtime/`` is ``gainlink``, ``hil/`` is
``gainlink.hil``; setuptools ``package-dir``). grimp, which import-linter builds its graph with, finds a package's
modules by walking the folder its spec names, so it would never see ``gainlink.hil``. This script mirrors both
folders as one package tree of symbolic links in a temporary folder, puts it first on the path and runs
``lint-imports`` there. Exit status is lint-imports' own.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = {"gainlink": ROOT / "runtime", "gainlink/hil": ROOT / "hil"}


def mirror(into: Path) -> None:
    """Real folders, linked .py files: grimp walks folders without following links."""
    for rel, src in SOURCES.items():
        for path in src.rglob("*.py"):
            if "__pycache__" in path.parts:
                continue
            target = into / rel / path.relative_to(src)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.symlink_to(path)


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="gainlink-layers-") as tmp:
        mirror(Path(tmp))
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([tmp, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
        lint = Path(sys.executable).with_name("lint-imports")
        return subprocess.run(
            [str(lint), str(ROOT / "pyproject.toml"), "--no-cache"], env=env, cwd=tmp, check=False
        ).returncode


if __name__ == "__main__":
    sys.exit(main())
