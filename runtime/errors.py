"""The gainlink exception tree.

Every error a user can cause derives from :class:`GainlinkError` and from the matching builtin,
so callers may catch either. The CLI turns any of them into one line and exit status 2.
"""

from __future__ import annotations

from collections.abc import Iterable


class GainlinkError(Exception):
    """Root of every gainlink error."""


class SpecError(GainlinkError, ValueError):
    """A plant spec is malformed, inconsistent or asks for something impossible."""


class DesignError(GainlinkError, ValueError):
    """The design cannot be done: unstabilizable, undetectable, bad weights, unstable result."""


class ArtifactError(GainlinkError, ValueError):
    """A gain artifact does not validate against its schema or its own invariants."""


class IntegrityError(ArtifactError):
    """A gain artifact's sha256 does not match its content."""


class DataError(GainlinkError, ValueError):
    """Input samples (CSV, scenario data) are malformed."""


class ToolchainError(GainlinkError, RuntimeError):
    """A compiler, QEMU or another external tool is missing or failed."""


class FirmwareError(GainlinkError, RuntimeError):
    """The firmware (host library, executable or target image) reported a failure."""


class TransportError(GainlinkError, ConnectionError):
    """A bus or link cannot be opened or failed during a run."""


class PeerTimeoutError(TransportError, TimeoutError):
    """A peer stayed silent past its deadline."""


class PlantError(GainlinkError, ValueError):
    """A plant model or FMU is missing, broken or does not fit the artifact."""


class ScenarioError(GainlinkError, ValueError):
    """A HIL scenario file is malformed."""


class VerificationError(GainlinkError, RuntimeError):
    """An implementation of the control law does not do what the float64 law does (one-step check)."""


class ParameterError(GainlinkError, RuntimeError):
    """A parameter upload failed (refused, not verified, or rolled back)."""


class LawError(GainlinkError, ValueError):
    """A law cannot do what was asked of it (its declaration says why), or no law runs such an artifact."""


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``" (did you mean 'x'?)"`` for the known name closest to a misspelt ``name`` (:func:`difflib.get_close_matches`,
    its default cut-off 0.6), or ``""`` when none is close: the tail of the one line that refuses ``name``."""
    import difflib

    close = difflib.get_close_matches(str(name), [str(k) for k in known], n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""
