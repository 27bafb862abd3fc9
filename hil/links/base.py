"""The transport plugin interface: how the bridge exchanges samples with the controller.

The bridge (plant side) turns each sample (sequence number, outputs ``y``, references ``r``) into
frames with :meth:`Transport.encode_sample`, may drop/delay/duplicate/reorder those frames (fault
injection), sends them with :meth:`Transport.send_frames`, and waits for the controller's
:class:`Command` with :meth:`Transport.receive_command`. A transport also says how the firmware
host executable must be started to speak it (:meth:`Transport.controller_argv`), because the bridge
starts and stops the controller process itself.

Transports are registered by kind in :data:`TRANSPORTS` and built from the scenario's
``[transport]`` table with :func:`gainlink.hil.links.config.transport_from_config`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gainlink.errors import TransportError
from gainlink.laws import flags

from ..registry import Registry

TRANSPORTS: Registry[Transport] = Registry(what="transport", error=TransportError)

#: Command status bits: the one table of a step's status flags (:mod:`gainlink.laws.flags`), the same bits on every
#: link and in the firmware (gl_flags.h).
STATUS_FAULT = flags.FAULT  #: the controller refused a non-finite sample and returned the safe command
STATUS_WATCHDOG = flags.WATCHDOG  #: the controller's watchdog expired (no measurement) and it holds the safe command
STATUS_CLIPPED = flags.CLIPPED  #: the fixed-point law clipped a sample or reference to its declared range
STATUS_OVERFLOW = flags.OVERFLOW  #: the fixed-point law's second-line saturation fired
STATUS_SIGMA_HELD = flags.SIGMA_HELD  #: the scheduled law held its last sigma (the new one was not finite)
STATUS_SIGMA_CLIPPED = flags.SIGMA_CLIPPED  #: the scheduled law clipped sigma to its points
STATUS_SIGMA_RATE = flags.SIGMA_RATE  #: the scheduled law limited sigma's change
STATUS_RESET = flags.RESET  #: the controller was reset: the command is its start command


@dataclass(frozen=True)
class Command:
    """One command received from the controller.

    Attributes
    ----------
    seq : int
        Sequence number of the sample this command answers (modulo the transport's counter range).
    u : numpy.ndarray
        The command, one value per input.
    saturated : numpy.ndarray
        Per input, whether the controller clamped it.
    status : int
        Bit set of ``STATUS_*``.
    t_ns : int
        ``time.perf_counter_ns()`` when the command was complete.
    wire : int
        The link's own flag word as it arrived (MAVLink: ``HIL_ACTUATOR_CONTROLS.flags``; CAN: the status byte), for
        whoever checks where the link puts the bits.
    """

    seq: int
    u: np.ndarray
    saturated: np.ndarray
    status: int
    t_ns: int
    wire: int = 0


class Transport(ABC):
    """Plant-side end of the link to the controller.

    Attributes
    ----------
    seq_modulo : int
        Sequence numbers are carried modulo this value.
    """

    seq_modulo: int = 1 << 16

    @abstractmethod
    def open(self) -> None:
        """Open the link; raise :class:`TransportError` with one clear line if it cannot open."""

    @abstractmethod
    def close(self) -> None:
        """Close the link (idempotent)."""

    @abstractmethod
    def encode_sample(self, *, seq: int, y: np.ndarray, r: np.ndarray) -> list[Any]:
        """The frames carrying one sample, in sending order."""

    @abstractmethod
    def send_frames(self, frames: Sequence[Any]) -> None:
        """Send frames produced by :meth:`encode_sample`."""

    @abstractmethod
    def receive_command(self, *, timeout: float) -> Command | None:
        """The next complete command, or ``None`` when none completes within ``timeout`` seconds."""

    def received_sample(self, *, y: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The sample as the controller decodes it (as float64): what a shadow law must be fed to see
        exactly the controller's inputs. Default: values travel as float32."""
        return y.astype(np.float32).astype(np.float64), r.astype(np.float32).astype(np.float64)

    def steps_on(self, seq: int) -> bool:
        """Whether the controller steps its law on the sample ``seq`` arriving next (a node may skip a duplicate or
        a stale sample): the order a shadow of its law must follow. Default: every sample it gets."""
        return True

    @abstractmethod
    def controller_argv(self) -> list[str]:
        """Command-line arguments that make the firmware host executable speak this link."""

    def describe(self) -> dict:
        """A JSON-able description for the report."""
        return {"kind": type(self).__name__}

    def silence_hint(self) -> str:
        """What the link heard from a controller that sends no commands, as a clause for the run's reason
        (e.g. answers refused for their signature); empty when the link has nothing to add."""
        return ""

    def __enter__(self) -> Transport:
        self.open()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
