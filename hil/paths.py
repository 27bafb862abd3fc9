"""Where the bridge caches what it builds (FMUs, the vcan VM): an ignored folder, never the source tree."""

from __future__ import annotations

import os
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def project_root() -> Path | None:
    """The source checkout holding this package (editable install), or ``None`` for an installed wheel."""
    root = _PACKAGE.parent
    return root if (root / "pyproject.toml").is_file() else None


def cache_dir(sub: str) -> Path:
    """``<checkout>/.cache/<sub>`` in a source checkout, else ``~/.cache/gainlink/<sub>``; created on demand."""
    root = project_root()
    base = root / ".cache" if root is not None and os.access(root, os.W_OK) else Path.home() / ".cache" / "gainlink"
    path = base / sub
    path.mkdir(parents=True, exist_ok=True)
    return path


def fmu_source_dir(name: str) -> Path:
    """The folder of one of the project's plant FMU sources (``hil/fmus/<name>``)."""
    return _PACKAGE / "fmus" / name


def fmu_source_names() -> list[str]:
    """Names of the plant FMUs the project ships as sources."""
    root = _PACKAGE / "fmus"
    return sorted(p.name for p in root.iterdir() if (p / "modelDescription.xml").is_file())
