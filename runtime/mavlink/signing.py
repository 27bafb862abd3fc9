"""MAVLink 2 message signing keys: the key file, a new key, and turning pymavlink's signing on.

The signing itself is pymavlink's (SHA-256 signature over the secret key, link id and a 48-bit timestamp in
10 us units since 2015-01-01, with replay protection per stream) on the ground side and mavgen's C library in
the firmware; this module only reads and writes keys and sets pymavlink's signing state.

A key file holds the 32-byte secret key as 64 hex digits (whitespace around them is ignored), the format the
firmware's ``gainlink_mavlink --signing-key FILE`` reads. It is a secret: written with mode 0600.
"""

from __future__ import annotations

import os
import secrets
import types
from collections.abc import Callable
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from ..errors import GainlinkError
from ..fileio import atomic_write_text, read_user_file

KEY_BYTES = 32

OPEN_MESSAGES = frozenset(
    {
        mavlink2.MAVLINK_MSG_ID_HEARTBEAT,
        mavlink2.MAVLINK_MSG_ID_PARAM_REQUEST_LIST,
        mavlink2.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
    }
)
"""What the firmware answers unsigned when it has a key (they change nothing; see gl_mav_node.h)."""


class SigningKeyError(GainlinkError, ValueError):
    """A signing key file is missing, unreadable or not 64 hex digits."""


def read_key(path: str | os.PathLike) -> bytes:
    """The 32-byte key in a key file.

    Raises
    ------
    SigningKeyError
        One line naming the file and what is wrong with it.
    """
    text = read_user_file(path, what="signing key file", error=SigningKeyError)
    digits = text.strip()
    if len(digits) != 2 * KEY_BYTES or any(c not in "0123456789abcdefABCDEF" for c in digits):
        raise SigningKeyError(
            f"signing key file {path}: expected exactly {2 * KEY_BYTES} hex digits (a 32-byte key, "
            f"as `gainlink mavlink keygen` writes), found {len(digits)} characters"
        )
    return bytes.fromhex(digits)


def new_key() -> bytes:
    """A new random key (``secrets``)."""
    return secrets.token_bytes(KEY_BYTES)


def write_key(path: str | os.PathLike, key: bytes, *, overwrite: bool = False) -> Path:
    """Write ``key`` as a key file (atomically, mode 0600); refuses to replace a file unless ``overwrite``."""
    path = Path(path)
    if len(key) != KEY_BYTES:
        raise SigningKeyError(f"a signing key has {KEY_BYTES} bytes, not {len(key)}")
    if path.exists() and not overwrite:
        raise SigningKeyError(f"{path} exists: not replacing a key file (remove it first)")
    atomic_write_text(path, key.hex() + "\n", mode=0o600)  # a secret: owner only, from the first byte
    return path


def enable(
    mav: mavlink2.MAVLink,
    key: bytes,
    *,
    link_id: int = 1,
    allow_unsigned: Callable[[mavlink2.MAVLink, int], bool] | None = None,
) -> None:
    """Sign everything ``mav`` sends and accept only correctly signed messages (plus ``allow_unsigned``'s).

    Uses pymavlink's own ``setup_signing`` (its initial timestamp is the time since 2015 in 10 us units, so a
    new session's timestamps follow the last one's): it sets the signing state of the ``mav`` it is given.
    """
    if len(key) != KEY_BYTES:
        raise SigningKeyError(f"a signing key has {KEY_BYTES} bytes, not {len(key)}")
    mavutil.mavfile.setup_signing(
        types.SimpleNamespace(mav=mav), key, sign_outgoing=True, allow_unsigned_callback=allow_unsigned, link_id=link_id
    )


def heartbeat_only(_mav: mavlink2.MAVLink, msgid: int) -> bool:
    """An ``allow_unsigned`` that lets a vehicle's HEARTBEAT through (to say it does not sign), nothing else."""
    return msgid == mavlink2.MAVLINK_MSG_ID_HEARTBEAT
