"""Files the user names: reading them (text, TOML) with one-line errors, and atomic output (nothing
half-written, nothing written at all when a step fails)."""

from __future__ import annotations

import os
import tempfile
import tomllib
from collections.abc import Mapping
from pathlib import Path

from .errors import GainlinkError


def read_user_file(path: str | os.PathLike, *, what: str, error: type[GainlinkError], binary: bool = False):
    """Read a file the user named; a missing file or a folder becomes one ``error`` naming ``what``.

    Returns ``bytes`` when ``binary`` else UTF-8 text.
    """
    path = Path(path)
    try:
        return path.read_bytes() if binary else path.read_text("utf-8")
    except FileNotFoundError:
        raise error(f"{what} {path} not found") from None
    except IsADirectoryError:
        raise error(f"{what} {path} is a directory") from None
    except PermissionError:
        raise error(f"{what} {path} cannot be read (permission denied)") from None
    except UnicodeDecodeError:
        raise error(f"{what} {path} is not UTF-8 text") from None


def parse_toml(text: str | bytes, *, what: str, error: type[GainlinkError]) -> dict:
    """Parse TOML text; a syntax error (or bytes that are not UTF-8) becomes one ``error`` naming ``what``."""
    try:
        return tomllib.loads(text.decode("utf-8") if isinstance(text, bytes) else text)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{what} is not valid TOML: {exc}") from None


def read_toml(path: str | os.PathLike, *, what: str, error: type[GainlinkError]) -> tuple[dict, bytes]:
    """Read and parse a TOML file the user named: ``(data, raw bytes)``; every failure is one ``error`` line."""
    raw = read_user_file(path, what=what, error=error, binary=True)
    return parse_toml(raw, what=f"{what} {path}", error=error), raw


def _default_mode() -> int:
    """The mode ``open()`` gives a new file: 0666 less the umask (mkstemp's 0600 would hide it from others)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, mode: int | None = None) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename.

    The file gets the permissions a plain ``open()`` would give it (readable by others under the usual umask),
    or ``mode`` (e.g. 0o600 for a secret), set before a byte is written.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, _default_mode() if mode is None else mode)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | os.PathLike, text: str, *, mode: int | None = None) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (``mode`` as in :func:`atomic_write_bytes`)."""
    atomic_write_bytes(path, text.encode("utf-8"), mode=mode)


def prepare_output_dir(out_dir: str | os.PathLike) -> Path:
    """Return ``out_dir`` as a Path, creating it; fail with one clear line if it is not a folder."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise GainlinkError(f"output path {out} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GainlinkError(f"cannot create output directory {out}: {exc.strerror}") from None
    return out


def publish_files(out_dir: str | os.PathLike, files: Mapping[str, bytes | str]) -> list[Path]:
    """Write every file of ``files`` (name -> content) into ``out_dir``, each atomically.

    Callers compute all content first and publish last, so a failing step leaves the folder untouched.
    """
    out = prepare_output_dir(out_dir)
    written = []
    for name, content in files.items():
        data = content.encode("utf-8") if isinstance(content, str) else content
        target = out / name
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(target, data)
        written.append(target)
    return written
