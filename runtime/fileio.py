"""Files the user names: reading them (text, TOML) with one-line errors, atomic output (nothing half-written,
nothing written at all when a step fails), and a host-wide lock for caches that processes fill concurrently."""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
import tomllib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO, Any, Literal, TypeAlias, overload

from .errors import GainlinkError

#: A path as the functions here take it: a string or an ``os.PathLike`` of one (``pathlib.Path``).
StrPath: TypeAlias = str | os.PathLike[str]


@overload
def read_user_file(path: StrPath, *, what: str, error: type[GainlinkError], binary: Literal[False] = False) -> str: ...
@overload
def read_user_file(path: StrPath, *, what: str, error: type[GainlinkError], binary: Literal[True]) -> bytes: ...
def read_user_file(path: StrPath, *, what: str, error: type[GainlinkError], binary: bool = False) -> str | bytes:
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


def parse_toml(text: str | bytes, *, what: str, error: type[GainlinkError]) -> dict[str, Any]:
    """Parse TOML text; a syntax error (or bytes that are not UTF-8) becomes one ``error`` naming ``what``."""
    try:
        return tomllib.loads(text.decode("utf-8") if isinstance(text, bytes) else text)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{what} is not valid TOML: {exc}") from None


def read_toml(path: StrPath, *, what: str, error: type[GainlinkError]) -> tuple[dict[str, Any], bytes]:
    """Read and parse a TOML file the user named: ``(data, raw bytes)``; every failure is one ``error`` line."""
    raw = read_user_file(path, what=what, error=error, binary=True)
    return parse_toml(raw, what=f"{what} {path}", error=error), raw


def _default_mode() -> int:
    """The mode ``open()`` gives a new file: 0666 less the umask (mkstemp's 0600 would hide it from others)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_writer(path: StrPath, *, binary: bool = False, mode: int | None = None) -> Iterator[IO[Any]]:
    """A file to write ``path`` through, as a stream: a temporary file in the same folder, renamed to ``path`` when
    the block ends without an exception and removed when it raises (``path`` is untouched then).

    Text (UTF-8) unless ``binary``; the permissions a plain ``open()`` would give (``mode`` as in
    :func:`atomic_write_bytes`), set before a byte is written.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, _default_mode() if mode is None else mode)
        with os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: StrPath, data: bytes, *, mode: int | None = None) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename.

    The file gets the permissions a plain ``open()`` would give it (readable by others under the usual umask),
    or ``mode`` (e.g. 0o600 for a secret), set before a byte is written.
    """
    with atomic_writer(path, binary=True, mode=mode) as fh:
        fh.write(data)


def atomic_write_text(path: StrPath, text: str, *, mode: int | None = None) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (``mode`` as in :func:`atomic_write_bytes`)."""
    atomic_write_bytes(path, text.encode("utf-8"), mode=mode)


def prepare_output_dir(out_dir: StrPath) -> Path:
    """Return ``out_dir`` as a Path, creating it; fail with one clear line if it is not a folder."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise GainlinkError(f"output path {out} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GainlinkError(f"cannot create output directory {out}: {exc.strerror}") from None
    return out


def publish_files(out_dir: StrPath, files: Mapping[str, bytes | str]) -> list[Path]:
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


@contextlib.contextmanager
def exclusive_lock(path: StrPath) -> Iterator[None]:
    """Hold an exclusive ``flock`` on ``path`` (created if missing) while the block runs.

    One process of the host at a time runs a block under the same lock file (other processes wait). Cache fills
    (a firmware build in its shared folder, an FMU, the vcan VM image, a download) take it around the work, check
    again inside whether another process finished it meanwhile, and publish with an atomic rename, so readers of a
    finished result never need the lock. Not reentrant: a process must not take the same lock twice.
    """
    lock = Path(path)
    lock.parent.mkdir(parents=True, exist_ok=True)
    with open(lock, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
