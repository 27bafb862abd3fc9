"""Upload a gain artifact to a vehicle over MAVLink: diff, verified pipelined sets, commit, persist,
and rollback of every changed parameter on any failure.

The steps of :func:`upload`:

1. wait for a vehicle HEARTBEAT (the first that is not a ground station's, or the one of the given target system
   and component; :class:`~gainlink.errors.PeerTimeoutError` when none comes);
2. ask for AUTOPILOT_VERSION: the integer encoding (bytewise or C-cast) it advertises, and whether the vehicle
   identifies as a gainlink node (``middleware_custom_version`` is ``gainlink``); a forced encoding that
   contradicts the advertised one is refused;
3. read the current value of every target parameter, check that each has the type the plan writes (``GL_HASH``
   and the read-only structure included), and compute the diff;
4. set the changed ones, a bounded window in flight, each verified by its echo, retried on timeout;
5. for the gainlink scheme, commit the staged set by setting ``GL_HASH`` (the loop swaps sets atomically between
   steps); on a gainlink node the commit is confirmed by AUTOPILOT_VERSION's ``uid``, the CRC-32 of the set the
   node runs (a mismatch is a failure). A vehicle that does not identify as a gainlink node only shows that it
   holds every value and ``GL_HASH``: that is all the result claims (``committed`` stays false);
6. with ``persist``, send MAV_CMD_PREFLIGHT_STORAGE and check the COMMAND_ACK.

Everything refused in steps 1-3 is refused before anything is written. When any step after the first set fails,
every parameter that was sent is set back to the value read in step 3 (and the old hash re-committed), and
:class:`UploadFailed` lists what happened.

A vehicle that requires signing (its messages carry signatures) but is spoken to without a key may
answer reads and ignore every set: when no set is answered at all and reading the parameters back
shows them unchanged, the upload fails with :data:`SIGNING_REQUIRED` (nothing was changed, nothing
to roll back).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn

from pymavlink.dialects.v20 import common as mavlink2

from ..errors import ParameterError, PeerTimeoutError
from ..shipping.artifact import Artifact
from ..shipping.law_c import label_of_id, law_label, mapping_refusal
from ..shipping.params import SIGNATURE_ID, STRUCTURE_ID
from .link import MavLink, carries_signature
from .params import (
    HASH_ID,
    INT32,
    REAL32,
    Encoding,
    Mapping,
    ParamSpec,
    firmware_params,
    load_mapping,
    mapped_params,
    same_value,
    type_name,
)
from .session import ParamSession, ParamValue, SetOutcome

log = logging.getLogger(__name__)

SIGNING_REQUIRED = "the vehicle requires MAVLink 2 signing (--signing-key)"

#: What a gainlink node puts in AUTOPILOT_VERSION's ``middleware_custom_version`` (``gl_mav_node.c``); such a node's
#: ``uid`` is the CRC-32 of the gain set it runs. Other autopilots' ``uid`` is a hardware id: never read as a set.
GAINLINK_NODE_MARK = b"gainlink"


@dataclass(frozen=True)
class Vehicle:
    """The vehicle an upload talks to, as its HEARTBEAT and AUTOPILOT_VERSION describe it.

    Attributes
    ----------
    system, component : int
        Its MAVLink system and component ids.
    autopilot : int
        ``MAV_AUTOPILOT`` of its HEARTBEAT.
    gainlink : bool
        Whether it identifies as a gainlink node (:data:`GAINLINK_NODE_MARK`): then a commit is confirmed by the
        CRC-32 in AUTOPILOT_VERSION's ``uid``.
    advertised : Encoding or None
        The integer encoding its AUTOPILOT_VERSION advertises; ``None`` when it names none or never came.
    versioned : bool
        Whether it answered the request for AUTOPILOT_VERSION at all.
    """

    system: int
    component: int
    autopilot: int
    gainlink: bool
    advertised: Encoding | None
    versioned: bool = True

    def describe(self) -> str:
        """``1/1 (MAV_AUTOPILOT_GENERIC, a gainlink node)``, ``... not a gainlink node)`` or ``... sent no
        AUTOPILOT_VERSION)``."""
        kind = "a gainlink node" if self.gainlink else "not a gainlink node"
        kind = kind if self.versioned else "sent no AUTOPILOT_VERSION"
        return f"{self.system}/{self.component} ({_enum_name('MAV_AUTOPILOT', self.autopilot)}, {kind})"


def _enum_name(enum: str, value: int) -> str:
    entry = mavlink2.enums.get(enum, {}).get(value)
    return entry.name if entry is not None else f"{enum} {value}"


@dataclass(frozen=True)
class ParamChange:
    """One parameter whose vehicle value differs from the artifact's."""

    name: str
    source: str
    ptype: int
    old: float | int
    new: float | int


@dataclass(frozen=True)
class UploadResult:
    """What an upload did.

    Attributes
    ----------
    vehicle : Vehicle
        The vehicle written to (or read, with ``dry_run``).
    encoding : Encoding
        Integer encoding used.
    changes : tuple of ParamChange
        The diff between the vehicle and the artifact (what was, or with ``dry_run`` would be, set).
    unchanged : int
        Parameters that already held the artifact's value.
    verified : int
        Sets verified by their echo (the commit included).
    sent : int
        PARAM_SETs sent, retries included.
    retries : int
        Requests sent again after a timeout or a mismatched echo, in every phase (reads, sets, commit, persist).
    hash_set : bool
        Whether ``GL_HASH`` was set and echoed (the commit request of the gainlink scheme).
    committed : bool
        Whether the commit is confirmed: ``GL_HASH`` echoed and the gainlink node's AUTOPILOT_VERSION ``uid`` is the
        new set's CRC-32. Always false on a vehicle that does not identify as a gainlink node: it can show that it
        holds the values, not that its loop runs them.
    persisted : bool
        Whether MAV_CMD_PREFLIGHT_STORAGE was acknowledged.
    dry_run : bool
        Whether nothing was written.
    seconds : float
        Wall time of the whole upload.
    """

    vehicle: Vehicle
    encoding: Encoding
    changes: tuple[ParamChange, ...]
    unchanged: int
    verified: int
    sent: int
    retries: int
    hash_set: bool
    committed: bool
    persisted: bool
    dry_run: bool
    seconds: float


class UploadFailed(ParameterError):
    """An upload failed; ``events`` says what happened, ``rolled_back`` whether every change was undone."""

    def __init__(self, message: str, *, events: tuple[str, ...], rolled_back: bool):
        super().__init__(message)
        self.events = events
        self.rolled_back = rolled_back


@dataclass(frozen=True)
class _Plan:
    specs: tuple[ParamSpec, ...]
    commit: bool
    checks: tuple[ParamSpec, ...]
    new_hash: int | None
    law: str | None = None  # the law the gainlink firmware must run (HEARTBEAT custom_mode)
    formats: tuple[ParamSpec, ...] = ()  # a fixed-point law's GL_FX_SIG and GL_FX_STRUCT


def _plan(artifact: Artifact, mapping: Mapping | None) -> _Plan:
    """What an upload writes: with a ``mapping`` the vehicle parameters it names (no commit); else the table of the
    law the gainlink firmware runs (gainlink.shipping.params.table), in its order: the read-only headers (checked
    before anything is written: dimensions as ``checks``, a fixed-point law's number formats and structure as
    ``formats``), ``GL_HASH``, then the gains, all committed at once through ``GL_HASH``."""
    if mapping is not None:
        why = mapping_refusal(artifact)
        if why is not None:
            raise ParameterError(f"{artifact.name} runs the {law_label(artifact)} law: {why}; nothing was changed")
        return _Plan(specs=mapped_params(artifact, mapping), commit=False, checks=(), new_hash=None)
    every = firmware_params(artifact)
    at = next(k for k, s in enumerate(every) if s.name == HASH_ID)
    header = every[:at]
    formats = tuple(s for s in header if s.name in (SIGNATURE_ID, STRUCTURE_ID))
    dims = tuple(s for s in header if s not in formats)
    return _Plan(specs=every[at + 1 :], commit=True, checks=dims, new_hash=int(every[at].value),
                 law=law_label(artifact), formats=formats)  # fmt: skip


def _fmt(v: float | int, ptype: int) -> str:
    return f"{v:.9g}" if ptype == REAL32 else str(int(v))


def format_changes(changes: tuple[ParamChange, ...]) -> list[str]:
    """One line per change: ``id  source  old -> new``."""
    return [f"{c.name:<16} {c.source:<12} {_fmt(c.old, c.ptype)} -> {_fmt(c.new, c.ptype)}" for c in changes]


def request_version(session: ParamSession):
    """The vehicle's AUTOPILOT_VERSION (MAV_CMD_REQUEST_MESSAGE, retried as the session's requests are), or
    ``None`` when it never comes."""
    return session.request_message(
        msg_id=mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION, wait=max(0.1, session.timeout), tries=session.retries + 1
    )


def advertised_encoding(version) -> Encoding | None:
    """The integer encoding AUTOPILOT_VERSION's capability flags advertise (``None``: none, or no message)."""
    if version is not None and version.capabilities & mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE:
        return Encoding.BYTEWISE
    if version is not None and version.capabilities & mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST:
        return Encoding.C_CAST
    return None


def detect_encoding(
    session: ParamSession, *, autopilot: int = mavlink2.MAV_AUTOPILOT_GENERIC, version=None
) -> Encoding:
    """Integer encoding of the vehicle's parameters.

    AUTOPILOT_VERSION's capability flags decide (``version``, asked for when not given); when they name neither
    encoding (or the message never comes) the autopilot type from HEARTBEAT does, as MAVLink's own SDK does:
    ArduPilot C-casts, everyone else (PX4, generic autopilots, MAVSDK servers) is bytewise.
    """
    version = version if version is not None else request_version(session)
    advertised = advertised_encoding(version)
    if advertised is not None:
        return advertised
    guess = Encoding.C_CAST if autopilot == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA else Encoding.BYTEWISE
    log.debug(
        "%s names no parameter encoding: %s integers (from the autopilot type %d)",
        "AUTOPILOT_VERSION" if version is not None else "no AUTOPILOT_VERSION arrived; it",
        guess.value,
        autopilot,
    )
    return guess


def upload(
    artifact: Artifact,
    *,
    connect: str,
    mapping: Mapping | str | Path | None = None,
    persist: bool = False,
    dry_run: bool = False,
    window: int = 16,
    timeout: float = 0.25,
    retries: int = 10,
    heartbeat_timeout: float = 5.0,
    encoding: Encoding | None = None,
    on_diff: Callable[[tuple[ParamChange, ...]], None] | None = None,
    link: MavLink | None = None,
    signing_key: bytes | None = None,
    target_system: int | None = None,
    target_component: int | None = None,
) -> UploadResult:
    """Upload ``artifact``'s gains to the vehicle at ``connect``.

    Parameters
    ----------
    artifact : Artifact
        The gain set.
    connect : str
        pymavlink connection URL (``udpout:127.0.0.1:14550``, ``udpin:0.0.0.0:14550``, serial device).
    mapping : Mapping or path, optional
        Map gains to the vehicle's own parameter names; without it the gainlink firmware scheme is used.
    persist : bool
        Send MAV_CMD_PREFLIGHT_STORAGE (write) after the set is applied, and check the ack.
    dry_run : bool
        Read and diff only.
    window : int
        PARAM_SETs in flight at most.
    timeout : float
        Seconds before a request is re-sent.
    retries : int
        Re-sends per parameter before it counts as failed.
    heartbeat_timeout : float
        Seconds to wait for the vehicle's heartbeat.
    encoding : Encoding, optional
        Integer encoding; by default detected (:func:`detect_encoding`). One that contradicts the encoding the
        vehicle's AUTOPILOT_VERSION advertises is refused.
    on_diff : callable, optional
        Called with the diff once the current values are read, before anything is written.
    link : MavLink, optional
        An already open link to use instead of opening ``connect`` (it is not closed).
    signing_key : bytes, optional
        MAVLink 2 signing key (:func:`gainlink.mavlink.signing.read_key`) for the link opened on ``connect``:
        every request is signed and only signed answers count.
    target_system, target_component : int, optional
        Upload to the vehicle with these ids; by default to the first that sends a HEARTBEAT and is not a ground
        station (logged at DEBUG level, and named in the result and in every error).

    Returns
    -------
    UploadResult

    Raises
    ------
    PeerTimeoutError
        No heartbeat within ``heartbeat_timeout``.
    TransportError
        With ``signing_key``: the vehicle does not sign with that key.
    ParameterError
        Before anything was written: a parameter is missing or has another type (``GL_HASH`` and the structure
        included), the firmware runs a loop of other dimensions, or ``encoding`` contradicts the vehicle's.
    UploadFailed
        After something was written: the set, commit or persist failed; every change was rolled back
        (``rolled_back``) or the events say which could not be.
    """
    if mapping is not None and not isinstance(mapping, Mapping):
        mapping = load_mapping(mapping)
    plan = _plan(artifact, mapping)
    t0 = time.perf_counter()
    own = link is None
    link = link or MavLink(connect, signing_key=signing_key)
    try:
        hb = link.wait_heartbeat(
            timeout=heartbeat_timeout, system=target_system, component=target_component, exclude_gcs=True
        )
        session = ParamSession(
            link,
            target_system=hb.get_srcSystem(),
            target_component=hb.get_srcComponent(),
            encoding=Encoding.C_CAST,
            window=window,
            timeout=timeout,
            retries=retries,
        )
        vehicle = _identify(session, hb)
        try:
            return _upload(
                session,
                plan=plan,
                persist=persist,
                dry_run=dry_run,
                t0=t0,
                vehicle=vehicle,
                encoding=encoding,
                on_diff=on_diff,
                needs_key=carries_signature(hb) and not link.signed,
            )
        except UploadFailed as exc:
            raise UploadFailed(
                f"vehicle {vehicle.describe()}: {exc}", events=exc.events, rolled_back=exc.rolled_back
            ) from None
        except ParameterError as exc:
            raise ParameterError(f"vehicle {vehicle.describe()}: {exc}") from None
    finally:
        if own:
            link.close()


def _identify(session: ParamSession, hb) -> Vehicle:
    """The vehicle of heartbeat ``hb``, described by its AUTOPILOT_VERSION (asked for once)."""
    version = request_version(session)
    vehicle = Vehicle(
        system=hb.get_srcSystem(),
        component=hb.get_srcComponent(),
        autopilot=int(hb.autopilot),
        gainlink=version is not None and bytes(version.middleware_custom_version) == GAINLINK_NODE_MARK,
        advertised=advertised_encoding(version),
        versioned=version is not None,
    )
    session.encoding = detect_encoding(session, autopilot=vehicle.autopilot, version=version)
    session.custom_mode = int(hb.custom_mode)
    log.debug("vehicle %s", vehicle.describe())
    return vehicle


def _use_encoding(session: ParamSession, vehicle: Vehicle, forced: Encoding | None) -> None:
    """Speak ``forced`` when given, unless the vehicle advertises another encoding (then its integers would be
    written as other numbers while every echo still looked right)."""
    if forced is None:
        return
    if vehicle.advertised is not None and forced is not vehicle.advertised:
        raise ParameterError(
            f"--encoding {forced.value} contradicts the vehicle's AUTOPILOT_VERSION, which advertises "
            f"{vehicle.advertised.value} integer parameters; nothing was changed"
        )
    session.encoding = forced


def _check_law(session: ParamSession, plan: _Plan) -> None:
    """Refuse, before anything is written, a set the gainlink firmware's law cannot run: another law (its HEARTBEAT's
    custom_mode), or a fixed-point law with other number formats or structure (GL_FX_SIG, GL_FX_STRUCT)."""
    runs = label_of_id(session.custom_mode)
    if plan.law is not None and runs != plan.law:
        raise ParameterError(
            f"the firmware runs the {runs} law and the artifact is a {plan.law} design: its gains cannot run there "
            "(build the firmware from it); nothing was changed"
        )
    if not plan.formats:
        return
    got, missing = session.read([s.name for s in plan.formats])
    _check_types(plan.formats, got)
    bad = [s for s in plan.formats if s.name in missing or int(got[s.name].value) != int(s.value)]
    if bad:
        what = "number formats" if bad[0].name == SIGNATURE_ID else "structure (non-zero terms, declared ranges)"
        have = "missing" if bad[0].name in missing else f"{int(got[bad[0].name].value) & 0xFFFFFFFF:08x}"
        raise ParameterError(
            f"the firmware's {runs} law has other {what} ({bad[0].name} {have}, the artifact's "
            f"{int(bad[0].value) & 0xFFFFFFFF:08x}): its integers would not mean the same there; nothing was changed"
        )


def _read_current(session: ParamSession, plan: _Plan, *, needs_key: bool) -> dict[str, ParamValue]:
    values: dict[str, ParamValue] = {}
    if plan.checks:  # the structure first: a loop of other dimensions is one clear error, not a list
        dims, missing = session.read([s.name for s in plan.checks])
        if needs_key and not dims:
            raise ParameterError(f"{SIGNING_REQUIRED}: it answered no unsigned parameter read; nothing was changed")
        if missing:
            raise ParameterError(
                f"the vehicle is not gainlink firmware (no {', '.join(sorted(missing))}); "
                "give --mapping for other autopilots; nothing was changed"
            )
        _check_types(plan.checks, dims)
        if any(int(dims[s.name].value) != int(s.value) for s in plan.checks):
            got = " ".join(f"{s.name}={int(dims[s.name].value)}" for s in plan.checks)
            want = " ".join(f"{s.name}={int(s.value)}" for s in plan.checks)
            raise ParameterError(
                f"the firmware runs a loop of other dimensions ({got}; the artifact has {want}); nothing was changed"
            )
        values.update(dims)
        _check_law(session, plan)
    got, missing = session.read([s.name for s in plan.specs] + ([HASH_ID] if plan.commit else []))
    if needs_key and not got:
        raise ParameterError(f"{SIGNING_REQUIRED}: it answered no unsigned parameter read; nothing was changed")
    if missing:
        listed = ", ".join(f"{n} ({why})" for n, why in sorted(missing.items())[:5])
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise ParameterError(f"vehicle lacks {len(missing)} parameter(s): {listed}{more}; nothing was changed")
    values.update(got)
    _check_types(
        plan.specs + ((ParamSpec(name=HASH_ID, ptype=INT32, value=0, source="crc32"),) if plan.commit else ()), got
    )
    return values


def _check_types(specs: tuple[ParamSpec, ...], got: dict[str, ParamValue]) -> None:
    """Refuse, before anything is written, a parameter the vehicle holds with another type than the plan's."""
    for s in specs:
        if s.name in got and got[s.name].ptype != s.ptype:
            raise ParameterError(
                f"parameter {s.name} is {type_name(got[s.name].ptype)} on the vehicle, {type_name(s.ptype)} in the "
                "plan; nothing was changed"
            )


def _upload(
    session: ParamSession,
    *,
    plan: _Plan,
    persist: bool,
    dry_run: bool,
    t0: float,
    vehicle: Vehicle,
    encoding: Encoding | None,
    on_diff: Callable[[tuple[ParamChange, ...]], None] | None,
    needs_key: bool,
) -> UploadResult:
    _use_encoding(session, vehicle, encoding)
    current = _read_current(session, plan, needs_key=needs_key)
    changes = _diff(plan, current)
    if on_diff is not None:
        on_diff(changes)
    old_hash = int(current[HASH_ID].value) if plan.commit else None
    need_commit = plan.commit and (bool(changes) or old_hash != plan.new_hash)
    writes = (
        _Writes()
        if dry_run
        else _write(session, plan=plan, changes=changes, commit=need_commit, confirm=vehicle.gainlink, persist=persist)
    )
    if writes.failure:
        _give_up(session, writes, changes=changes, old_hash=old_hash, needs_key=needs_key)
    return UploadResult(
        vehicle=vehicle,
        encoding=session.encoding,
        changes=changes,
        unchanged=len(plan.specs) - len(changes),
        verified=writes.verified,
        sent=writes.sent,
        retries=session.resent,
        hash_set=writes.hash_set,
        committed=writes.committed,
        persisted=writes.persisted,
        dry_run=dry_run,
        seconds=time.perf_counter() - t0,
    )


def _diff(plan: _Plan, current: dict[str, ParamValue]) -> tuple[ParamChange, ...]:
    """The planned parameters whose vehicle value differs from the artifact's."""
    return tuple(
        ParamChange(name=s.name, source=s.source, ptype=s.ptype, old=current[s.name].value, new=s.value)
        for s in plan.specs
        if not same_value(a=current[s.name].value, b=s.value, ptype=s.ptype)
    )


@dataclass
class _Writes:
    """What the writing steps did: every set outcome (the changes first, then the commit), the counts, the first
    failure (``""`` when none) and the events so far."""

    outcomes: list[SetOutcome] = field(default_factory=list)
    sent: int = 0
    verified: int = 0
    hash_set: bool = False
    committed: bool = False
    persisted: bool = False
    failure: str = ""
    events: list[str] = field(default_factory=list)


def _write(
    session: ParamSession,
    *,
    plan: _Plan,
    changes: tuple[ParamChange, ...],
    commit: bool,
    confirm: bool,
    persist: bool,
) -> _Writes:
    """Set the changes, then commit (confirmed by the node when ``confirm``) and persist as asked, stopping at the
    first failure."""
    out = session.set([(c.name, c.ptype, c.new) for c in changes], stop_on_failure=True)
    writes = _Writes(outcomes=[out], sent=out.sent, verified=len(out.verified), failure=_describe(out, what="set"))
    if not writes.failure and commit:
        _commit(session, writes, new_hash=plan.new_hash)
    if not writes.failure and commit and confirm:
        _confirm_commit(session, writes, new_hash=plan.new_hash)
    if not writes.failure and persist:
        _persist(session, writes)
    return writes


def _commit(session: ParamSession, writes: _Writes, *, new_hash: int | None) -> None:
    """Set ``GL_HASH``: the firmware applies the staged set to the loop."""
    c = session.set([(HASH_ID, INT32, new_hash)])
    writes.outcomes.append(c)
    writes.sent += c.sent
    if c.ok:
        writes.hash_set, writes.verified = True, writes.verified + 1
        writes.events.append(f"set {HASH_ID}={new_hash} (echoed)")
    else:
        writes.failure = _describe(c, what="commit (the firmware refused the staged set)")


def _confirm_commit(session: ParamSession, writes: _Writes, *, new_hash: int | None) -> None:
    """On a gainlink node: the CRC-32 in AUTOPILOT_VERSION's ``uid`` (the set the node runs) is the new set's."""
    want = (new_hash or 0) & 0xFFFFFFFF
    version = request_version(session)
    if version is None:
        writes.failure = "commit not confirmed: the gainlink node sent no AUTOPILOT_VERSION after the commit"
    elif version.uid != want:
        writes.failure = (
            f"commit not confirmed: {HASH_ID} was echoed, but the node's AUTOPILOT_VERSION uid says it runs "
            f"0x{version.uid:x}, not crc32 0x{want:08x}"
        )
    else:
        writes.committed = True
        writes.events.append(f"commit confirmed: the node runs crc32 0x{want:08x} (AUTOPILOT_VERSION uid)")


def _persist(session: ParamSession, writes: _Writes) -> None:
    """MAV_CMD_PREFLIGHT_STORAGE (write), acknowledged as accepted."""
    try:
        ack = session.command(command=mavlink2.MAV_CMD_PREFLIGHT_STORAGE, params=(1.0, -1.0))
    except PeerTimeoutError as exc:
        writes.failure = f"persist failed: {exc}"
        return
    if ack != mavlink2.MAV_RESULT_ACCEPTED:
        writes.failure = f"persist refused: COMMAND_ACK result {_result_name(ack)}"
        return
    writes.persisted = True


def _give_up(
    session: ParamSession,
    writes: _Writes,
    *,
    changes: tuple[ParamChange, ...],
    old_hash: int | None,
    needs_key: bool,
) -> NoReturn:
    """Raise for a failed write: the signing refusal when the vehicle ignored every set, else roll back."""
    writes.events.insert(0, writes.failure)
    skipped = writes.outcomes[0].skipped
    touched = tuple(c for c in changes if c.name not in skipped)  # never-sent ones need no restore
    sent_hash = old_hash if len(writes.outcomes) > 1 else None
    if needs_key and _all_ignored(session, writes.outcomes, changes=touched, old_hash=sent_hash):
        raise ParameterError(
            f"{SIGNING_REQUIRED}: it ignored every unsigned parameter set (its own messages are signed); "
            "nothing was changed"
        )
    _fail(
        session,
        writes.failure,
        changes=touched,
        committed=writes.hash_set,
        old_hash=old_hash,
        events=writes.events,
    )


def _all_ignored(
    session: ParamSession, outcomes: list, *, changes: tuple[ParamChange, ...], old_hash: int | None
) -> bool:
    """Whether the vehicle answered none of the sets and, read again, still holds the old value of every parameter
    that was sent (``GL_HASH`` too when ``old_hash`` is given)."""
    if any(o.verified or o.refused for o in outcomes):
        return False
    items = [(c.name, c.ptype, c.old) for c in changes] + ([(HASH_ID, INT32, old_hash)] if old_hash is not None else [])
    got, missing = session.read([name for name, _, _ in items])
    return not missing and all(same_value(a=got[name].value, b=old, ptype=t) for name, t, old in items)


def _fail(
    session: ParamSession,
    failure: str,
    *,
    changes: tuple[ParamChange, ...],
    committed: bool,
    old_hash: int | None,
    events: list[str],
) -> NoReturn:
    """Roll ``changes`` (and a commit) back and raise :class:`UploadFailed` saying whether that worked."""
    rolled_back = _rollback(session, changes=changes, committed=committed, old_hash=old_hash, events=events)
    state = "every changed parameter was restored" if rolled_back else "ROLLBACK INCOMPLETE"
    raise UploadFailed(f"upload failed: {failure}; {state}", events=tuple(events), rolled_back=rolled_back)


def _describe(out, *, what: str) -> str:
    parts = []
    for name, (value, reason) in sorted(out.refused.items()):
        parts.append(f"{name} refused (vehicle kept {value!r}{', ' + reason if reason else ''})")
    for name in out.unanswered:
        parts.append(f"{name} never echoed")
    if parts and out.skipped:
        parts.append(f"{len(out.skipped)} not sent")
    return f"{what}: " + "; ".join(parts) if parts else ""


def _result_name(code: int) -> str:
    for k, v in vars(mavlink2).items():
        if k.startswith("MAV_RESULT_") and v == code and k != "MAV_RESULT_ENUM_END":
            return k
    return str(code)


def _rollback(
    session: ParamSession,
    *,
    changes: tuple[ParamChange, ...],
    committed: bool,
    old_hash: int | None,
    events: list[str],
) -> bool:
    if not changes and not committed:
        events.append("nothing had been changed")
        return True
    back = session.set([(c.name, c.ptype, c.old) for c in changes])
    for name in back.verified:
        events.append(f"restored {name}")
    ok = back.ok
    for name, (value, reason) in back.refused.items():
        events.append(f"could NOT restore {name} (vehicle holds {value!r}{', ' + reason if reason else ''})")
    for name in back.unanswered:
        events.append(f"could NOT restore {name} (no echo)")
    if committed and old_hash is not None:
        h = session.set([(HASH_ID, INT32, old_hash)])
        if h.ok:
            events.append(f"re-committed the previous gain set {HASH_ID}={old_hash}")
        else:
            ok = False
            events.append(f"could NOT re-commit the previous gain set {HASH_ID}={old_hash}")
    return ok


def dry_run_against(
    artifact: Artifact,
    session: ParamSession,
    *,
    target: tuple[int, int],
    mapping: Mapping | str | Path | None = None,
    on_diff: Callable[[tuple[ParamChange, ...]], None] | None = None,
) -> UploadResult:
    """:func:`upload`'s dry run against a session that is no link (:class:`.params_file.ValuesSession`: a vehicle's
    saved ``.params`` file): the same plan, checks, refusals and diff; nothing is sent anywhere."""
    if mapping is not None and not isinstance(mapping, Mapping):
        mapping = load_mapping(mapping)
    plan = _plan(artifact, mapping)
    vehicle = Vehicle(system=target[0], component=target[1], autopilot=0, gainlink=plan.commit, advertised=None,
                      versioned=False)  # a file says no more of the vehicle than its ids  # fmt: skip
    return _upload(session, plan=plan, persist=False, dry_run=True, t0=time.perf_counter(), vehicle=vehicle,
                   encoding=None, on_diff=on_diff, needs_key=False)  # fmt: skip
