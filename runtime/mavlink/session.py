"""The MAVLink parameter protocol, pipelined: reads and verified sets with a bounded window in flight.

One :class:`ParamSession` talks to one component. Every request is retried on timeout; a
``PARAM_SET`` counts as verified only when a ``PARAM_VALUE`` for the same id echoes exactly the
value sent. An echo with another value (the vehicle refused, or a stale duplicate on a lossy link)
is retried too, and reported as refused once the retries are used up.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mavlink2

from ..errors import PeerTimeoutError
from .link import MavLink, raw_param_value
from .params import Encoding, decode_value, encode_value, same_value

log = logging.getLogger(__name__)

_PARAM_ERRORS = {
    mavlink2.MAV_PARAM_ERROR_DOES_NOT_EXIST: "does not exist",
    mavlink2.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE: "value out of range",
    mavlink2.MAV_PARAM_ERROR_PERMISSION_DENIED: "permission denied",
    mavlink2.MAV_PARAM_ERROR_COMPONENT_NOT_FOUND: "component not found",
    mavlink2.MAV_PARAM_ERROR_READ_ONLY: "read-only",
}


@dataclass(frozen=True)
class ParamValue:
    """A parameter as the vehicle reported it."""

    name: str
    ptype: int
    value: float | int
    index: int
    count: int


@dataclass(frozen=True)
class SetOutcome:
    """What happened to a batch of PARAM_SETs.

    Attributes
    ----------
    verified : tuple of str
        Ids whose echo matched the value sent.
    refused : dict
        Id -> (value the vehicle kept, reason or ``""``) for sets echoed with another value.
    unanswered : tuple of str
        Ids that never got an echo.
    skipped : tuple of str
        Ids never sent because an earlier one failed (``stop_on_failure``).
    sent : int
        PARAM_SETs sent, retries included.
    retries : int
        Re-sends after a timeout or a mismatched echo.
    """

    verified: tuple[str, ...]
    refused: dict = field(default_factory=dict)
    unanswered: tuple[str, ...] = ()
    skipped: tuple[str, ...] = ()
    sent: int = 0
    retries: int = 0

    @property
    def ok(self) -> bool:
        """Whether every set was verified."""
        return not self.refused and not self.unanswered


@dataclass
class _Flight:
    name: str
    deadline: float
    attempts: int
    ptype: int = 0
    raw: bytes = b""
    mismatch: float | int | None = None


class ParamSession:
    """Parameter protocol client for one target component.

    Parameters
    ----------
    link : MavLink
        The open link.
    target_system, target_component : int
        The vehicle component that owns the parameters.
    encoding : Encoding
        Integer encoding of ``param_value``.
    window : int
        Requests in flight at most.
    timeout : float
        Seconds to wait for an answer before re-sending.
    retries : int
        Re-sends per parameter before giving up.
    """

    def __init__(
        self,
        link: MavLink,
        *,
        target_system: int,
        target_component: int,
        encoding: Encoding,
        window: int = 16,
        timeout: float = 0.25,
        retries: int = 10,
    ):
        self.link = link
        self.target_system = target_system
        self.target_component = target_component
        self.encoding = encoding
        self.window = max(1, int(window))
        self.timeout = float(timeout)
        self.retries = int(retries)
        self.resent = 0  # every request sent again after a timeout (reads, list, sets, commands)
        self.custom_mode = 0  # the vehicle HEARTBEAT's custom_mode (the gainlink firmware: the law it runs)

    # -- replies -------------------------------------------------------------------------------
    def _ours(self, m) -> bool:
        return m.get_srcSystem() == self.target_system and m.get_srcComponent() == self.target_component

    def _replies(self, wait: float):
        for m in self.link.poll(wait):
            t = m.get_type()
            if t in ("PARAM_VALUE", "PARAM_ERROR") and self._ours(m):
                yield m

    # -- reads ---------------------------------------------------------------------------------
    def read(self, names: list[str]) -> tuple[dict[str, ParamValue], dict[str, str]]:
        """Read parameters by id (PARAM_REQUEST_READ, pipelined).

        Returns
        -------
        values : dict
            Id -> :class:`ParamValue` for every id answered.
        missing : dict
            Id -> reason for ids that the vehicle says do not exist or never answered.
        """
        pending = deque(dict.fromkeys(names))
        flying: dict[str, _Flight] = {}
        values: dict[str, ParamValue] = {}
        missing: dict[str, str] = {}

        def send(name: str, attempts: int) -> None:
            self.link.send(
                mavlink2.MAVLink_param_request_read_message(
                    self.target_system, self.target_component, name.encode("ascii"), -1
                )
            )
            flying[name] = _Flight(name=name, deadline=time.monotonic() + self.timeout, attempts=attempts)

        while pending or flying:
            while pending and len(flying) < self.window:
                send(pending.popleft(), 1)
            wait = max(0.0, min(f.deadline for f in flying.values()) - time.monotonic())
            for m in self._replies(wait):
                name = m.param_id
                if name not in flying:
                    continue
                if m.get_type() == "PARAM_ERROR":
                    missing[name] = _PARAM_ERRORS.get(m.error, f"error {m.error}")
                    del flying[name]
                    continue
                raw = raw_param_value(m)
                values[name] = ParamValue(
                    name=name,
                    ptype=m.param_type,
                    value=decode_value(raw=raw, ptype=m.param_type, encoding=self.encoding),
                    index=m.param_index,
                    count=m.param_count,
                )
                del flying[name]
            now = time.monotonic()
            for name, f in list(flying.items()):
                if f.deadline <= now:
                    if f.attempts > self.retries:
                        missing[name] = f"no PARAM_VALUE after {f.attempts} requests"
                        del flying[name]
                    else:
                        self.resent += 1
                        send(name, f.attempts + 1)
        return values, missing

    def read_all(self, *, timeout: float = 5.0) -> dict[str, ParamValue]:
        """Read the whole list (PARAM_REQUEST_LIST), then fetch any index that was lost by index.

        Raises
        ------
        PeerTimeoutError
            When the list does not complete within ``timeout`` seconds.
        """
        self.link.send(mavlink2.MAVLink_param_request_list_message(self.target_system, self.target_component))
        deadline = time.monotonic() + timeout
        by_index: dict[int, ParamValue] = {}
        count = None
        quiet_since = time.monotonic()
        while count is None or len(by_index) < count:
            now = time.monotonic()
            if now > deadline:
                got = len(by_index)
                raise PeerTimeoutError(
                    f"parameter list incomplete after {timeout:g} s ({got} of {count if count is not None else '?'})"
                )
            got_any = False
            for m in self._replies(0.05):
                if m.get_type() != "PARAM_VALUE":
                    continue
                got_any = True
                count = m.param_count
                raw = raw_param_value(m)
                by_index[m.param_index] = ParamValue(
                    name=m.param_id,
                    ptype=m.param_type,
                    value=decode_value(raw=raw, ptype=m.param_type, encoding=self.encoding),
                    index=m.param_index,
                    count=m.param_count,
                )
            if got_any:
                quiet_since = time.monotonic()
            elif count is not None and time.monotonic() - quiet_since > self.timeout:
                for idx in [i for i in range(count) if i not in by_index][: self.window]:
                    self.resent += 1
                    self.link.send(
                        mavlink2.MAVLink_param_request_read_message(self.target_system, self.target_component, b"", idx)
                    )
                quiet_since = time.monotonic()
            elif count is None and time.monotonic() - quiet_since > 4 * self.timeout:
                self.resent += 1
                self.link.send(mavlink2.MAVLink_param_request_list_message(self.target_system, self.target_component))
                quiet_since = time.monotonic()
        return {pv.name: pv for pv in sorted(by_index.values(), key=lambda p: p.index)}

    # -- sets ----------------------------------------------------------------------------------
    def set(self, items: list[tuple[str, int, float | int]], *, stop_on_failure: bool = False) -> SetOutcome:
        """Set parameters ``(id, type, value)`` with a bounded window, verifying every echo.

        With ``stop_on_failure``, nothing new is sent once one set is refused or unanswered (those in
        flight are still seen through); the rest are reported as ``skipped``.
        """
        batch = _SetBatch(self, items)
        while batch.pending or batch.flying:
            if stop_on_failure:
                batch.skip_rest_after_failure()
            batch.fill_window()
            if not batch.flying:
                break
            for m in self._replies(batch.wait()):
                batch.take_echo(m)
            batch.retry_overdue()
        return batch.outcome()

    # -- commands ------------------------------------------------------------------------------
    def command(self, *, command: int, params: tuple[float, ...] = (), wait: float | None = None) -> int:
        """Send COMMAND_LONG (retried with rising confirmation) and return the COMMAND_ACK result.

        Raises
        ------
        PeerTimeoutError
            When no final COMMAND_ACK arrives.
        """
        p = (tuple(params) + (0.0,) * 7)[:7]
        per_try = self.timeout * 4 if wait is None else wait
        for confirmation in range(self.retries + 1):
            self.resent += confirmation > 0
            self.link.send(
                mavlink2.MAVLink_command_long_message(
                    self.target_system, self.target_component, command, confirmation, *p
                )
            )
            deadline = time.monotonic() + per_try
            while (left := deadline - time.monotonic()) > 0:
                for m in self.link.poll(left):
                    if m.get_type() == "COMMAND_ACK" and self._ours(m) and m.command == command:
                        if m.result == mavlink2.MAV_RESULT_IN_PROGRESS:
                            deadline = time.monotonic() + per_try
                            continue
                        return int(m.result)
        raise PeerTimeoutError(f"no COMMAND_ACK for command {command} after {self.retries + 1} tries")

    def request_message(self, *, msg_id: int, wait: float = 0.5, tries: int = 3):
        """Ask for one message (MAV_CMD_REQUEST_MESSAGE) and return it, or ``None`` if it never comes."""
        for _ in range(tries):
            self.link.send(
                mavlink2.MAVLink_command_long_message(
                    self.target_system,
                    self.target_component,
                    mavlink2.MAV_CMD_REQUEST_MESSAGE,
                    0,
                    float(msg_id),
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                )
            )
            deadline = time.monotonic() + wait
            while (left := deadline - time.monotonic()) > 0:
                for m in self.link.poll(left):
                    if m.get_msgId() == msg_id and self._ours(m):
                        return m
        return None


class _SetBatch:
    """One batch of PARAM_SETs of a :class:`ParamSession`: what is still to send, what is in flight, what is
    settled (verified, refused, unanswered, skipped), and the counts."""

    def __init__(self, session: ParamSession, items: list[tuple[str, int, float | int]]):
        self.session = session
        self.items = items
        self.pending = deque(items)
        self.flying: dict[str, _Flight] = {}
        self.reasons: dict[str, str] = {}
        self.skipped: tuple[str, ...] = ()
        self.verified: list[str] = []
        self.refused: dict = {}
        self.unanswered: list[str] = []
        self.sent = self.retries = 0

    def send(self, f: _Flight) -> None:
        """Send ``f``'s PARAM_SET and put it in flight with a new deadline."""
        s = self.session
        s.link.send_param_set(
            target_system=s.target_system,
            target_component=s.target_component,
            name=f.name,
            raw=f.raw,
            param_type=f.ptype,
        )
        self.sent += 1
        f.deadline = time.monotonic() + s.timeout
        self.flying[f.name] = f

    def give_up_or_resend(self, f: _Flight) -> None:
        """Take ``f`` out of flight: send it again, or with its retries used up, settle it as refused (an echo
        with another value came) or unanswered."""
        del self.flying[f.name]
        if f.attempts > self.session.retries:
            if f.mismatch is not None:
                self.refused[f.name] = (f.mismatch, self.reasons.get(f.name, ""))
            else:
                self.unanswered.append(f.name)
            return
        f.attempts += 1
        self.retries += 1
        self.session.resent += 1
        self.send(f)

    def skip_rest_after_failure(self) -> None:
        """Once a set failed, send nothing new: what is still pending is skipped."""
        if (self.refused or self.unanswered) and self.pending:
            self.pending.clear()
            self.skipped = tuple(
                n
                for n, _, _ in self.items
                if n not in self.flying
                and n not in self.verified
                and n not in self.refused
                and n not in self.unanswered
            )

    def fill_window(self) -> None:
        """Send pending sets until the window is full."""
        while self.pending and len(self.flying) < self.session.window:
            name, ptype, value = self.pending.popleft()
            raw = encode_value(value=value, ptype=ptype, encoding=self.session.encoding)
            self.send(_Flight(name=name, deadline=0.0, attempts=1, ptype=ptype, raw=raw))

    def wait(self) -> float:
        """Seconds until the first deadline of those in flight."""
        return max(0.0, min(f.deadline for f in self.flying.values()) - time.monotonic())

    def take_echo(self, m) -> None:
        """A PARAM_VALUE or PARAM_ERROR: verify the set it answers, or note why it failed and resend it."""
        f = self.flying.get(m.param_id)
        if f is None:
            return
        if m.get_type() == "PARAM_ERROR":
            self.reasons[f.name] = _PARAM_ERRORS.get(m.error, f"error {m.error}")
            return
        encoding = self.session.encoding
        got = raw_param_value(m)
        if m.param_type == f.ptype and same_value(
            a=decode_value(raw=got, ptype=f.ptype, encoding=encoding),
            b=decode_value(raw=f.raw, ptype=f.ptype, encoding=encoding),
            ptype=f.ptype,
        ):
            self.verified.append(f.name)
            del self.flying[f.name]
        else:
            f.mismatch = decode_value(raw=got, ptype=m.param_type, encoding=encoding)
            log.debug("echo of %s is %r, not the value sent", f.name, f.mismatch)
            self.give_up_or_resend(f)

    def retry_overdue(self) -> None:
        """Resend (or give up on) every set in flight past its deadline."""
        now = time.monotonic()
        for f in [f for f in self.flying.values() if f.deadline <= now]:
            self.give_up_or_resend(f)

    def outcome(self) -> SetOutcome:
        """The batch's :class:`SetOutcome`."""
        return SetOutcome(
            verified=tuple(self.verified),
            refused=self.refused,
            unanswered=tuple(self.unanswered),
            skipped=self.skipped,
            sent=self.sent,
            retries=self.retries,
        )
