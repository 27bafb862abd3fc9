"""HIL scenarios: a TOML file naming the artifact, plant, transport, timing, profiles and faults.

Example::

    name = "pendulum_udp"
    artifact = "out/demo/gains.json"      # relative to the scenario file
    duration = 10.0                        # s of plant time
    mode = "lockstep"                      # lockstep | realtime
    controller = "firmware"                # firmware (host app) | reference (Python node) | qemu (Cortex-M image)
    firmware = "path/to/gainlink_can"      # optional: a prebuilt executable or, for qemu, ELF (default: built)
    board = "mps2-an386"                   # qemu: a board whose image serves its UART (microbit: fixed point, slcan)
    step_timeout = 0.05                    # lockstep: wait per command [s]
    peer_timeout = 1.0                     # end the run when the controller is silent this long [s]
    period = 0.01                          # realtime: tick [s] (default: the artifact's Ts)
    sched_fifo = true                      # realtime: SCHED_FIFO when permitted
    pm_qos = true                          # realtime: hold /dev/cpu_dma_latency at 0 us when permitted
    overrun = "skip"                       # realtime: skip | catch_up (ticks missed in a stall, see below)
    affinity = "auto"                      # auto | shared | separate | none (CPU placement, see below)
    seed = 1
    twin = true                            # run the float64 twin of the loop beside it (see below)
    model_twin = true                      # and the law around the design's own linear model (see below)

    [plant]        kind = "fmu", fmu = "cart_pendulum", outputs = ["x", "theta"]
    [transport]    interface = "udp_multicast", channel = "239.74.163.2", hop_limit = 0, fd = true
                   # optional: encoding = "int16", ranges = { x = [-5.0, 5.0], theta = [-1.0, 1.0], r_x = [-5.0, 5.0] }
                   # an empty table: no link, the law runs in process (SIL)
    [initial_state] theta = 0.1
    [reference.x]  kind = "step", at = 1.0, value = 0.5     # constant | step | square | sine | ramp | sweep
                   # absolute; without a profile, or without initial/offset, a reference holds the
                   # tracked output's value at the artifact's operating point (0 without one)
    [noise]        theta = 0.001                           # std dev per output
    [[disturbances]] input = "F", start = 2.0, stop = 2.1, value = 5.0
    [[faults]]     kind = "drop", start = 3.0, stop = 3.1, every = 1
                   # kind: drop | delay | duplicate | reorder | silent | crash | nan
                   # nan: the sample's measured outputs sent as NaN (every law, in process too)
                   # probability = 0.05: each sample the window and ``every`` select is hit with this probability
                   # (drawn from the run's seed): a random loss rate instead of a pattern

``affinity`` places the bridge and the controller process on CPUs for the run: ``shared`` (one CPU
for both: each hand-over is a local context switch, the fastest lockstep), ``separate`` (one CPU
each: what two busy-polling peers need), ``none`` (the kernel decides); ``auto`` (default) is
``shared`` in lockstep, ``separate`` with ``busy_poll_us`` in the transport, else ``none``.

``controller = "qemu"`` runs the Cortex-M image of ``board``'s core (``gainlink firmware build --target cortex-mN
--board BOARD``, or the ELF named by ``firmware``) in ``qemu-system-arm`` on ``board`` (mps2-an386 by default;
any board of gainlink.firmware.targets whose image carries the bus nodes; the micro:bit's only the slcan node of a
fixed-point artifact), speaking on its UART, which QEMU serves as a
TCP socket: ``[transport] kind = "mavlink", url = "tcp:HOST:PORT"`` (MAVLink) or ``interface = "slcan",
channel = "socket://HOST:PORT"`` (CAN through slcan, classic frames). The bridge starts QEMU, waits for the
image's banner, runs the loop and always stops QEMU. ``affinity = "auto"`` leaves QEMU's threads to the
kernel.

``pm_qos`` asks the kernel for a 0 us CPU wake-up latency for a realtime run (``/dev/cpu_dma_latency``,
root only, as cyclictest does): idle CPUs poll instead of halting, which on a virtual machine spares
every wake-up a trip through the hypervisor (here it took 1 kHz runs from hundreds of missed
deadlines per 5 s to none or a few).

``overrun`` says what a realtime run does with ticks that passed while the bridge was stalled (the
machine paused it for a period or more): ``skip`` (default) moves on to the tick now due and lets
the plant run through the missed ones under the held command, as a physical plant would — each is
a deadline miss and counted in ``overruns``; ``catch_up`` runs the missed ticks back to back.

``twin`` runs a float64 twin of the whole loop in step with the run (:mod:`gainlink.proof.twin`): the reference
law around a second instance of the same plant, same noise, references, disturbances and initial state,
no link and no faults. The report compares the run with it (command and output deviations, IAE
difference): what float32, the encoding, the link, timing and faults cost the closed loop.
``model_twin`` runs the same law around the design's own linear model (:mod:`.model_twin`), started where
the plant starts: the report gives how far the plant departs from the model the controller believes in.

A scheduled artifact (in process or over its link, as every law: :mod:`.bridge`) takes its sigma from the measured
output the schedule names or, when sigma is an external signal, from a profile per external signal, written like a
reference's::

    [schedule_signal.load]  kind = "sweep", low = 0.04, high = 1.0, rate = 0.1, start = 2.0, cycles = 1
                   # sweep: low until start, to high at rate (units/s) and back at once (cycles times), then low

``sigma_rate_limit = false`` runs a scheduled artifact's law without its ``rate_max`` (a copy re-sealed without
it; the report's ``run.artifact`` says so): a probe of the design's verdict on a moving sigma, as the campaign
over sigma rate (``examples/campaigns/tank_sigma_rate.toml``) runs it; never a way to fly.

Unknown keys anywhere are refused with one line naming them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gainlink.errors import ScenarioError, did_you_mean
from gainlink.fileio import read_toml
from gainlink.firmware.targets import BOARDS as _FIRMWARE_BOARDS

from .scheduler import AFFINITIES, OVERRUN_POLICIES

TOP_KEYS = {
    "name",
    "artifact",
    "plant",
    "transport",
    "duration",
    "mode",
    "controller",
    "step_timeout",
    "peer_timeout",
    "period",
    "sched_fifo",
    "seed",
    "twin",
    "model_twin",
    "initial_state",
    "reference",
    "noise",
    "disturbances",
    "faults",
    "description",
    "firmware",
    "affinity",
    "overrun",
    "pm_qos",
    "board",
    "schedule_signal",
    "sigma_rate_limit",
}
CONTROLLERS = ("firmware", "reference", "qemu")
BOARDS = tuple(
    sorted(
        (b.name for b in _FIRMWARE_BOARDS.values() if b.serves or b.slcan_laws),
        key=lambda n: n != "mps2-an386",
    )
)
MODES = ("lockstep", "realtime")
FAULT_KINDS = ("drop", "delay", "duplicate", "reorder", "silent", "crash", "nan")
PROFILE_KEYS = {
    "constant": {"value"},
    "step": {"at", "value", "initial"},
    "square": {"period", "amplitude", "offset"},
    "sine": {"frequency", "amplitude", "offset"},
    "ramp": {"start", "slope", "stop", "initial"},
    "sweep": {"low", "high", "rate", "start", "cycles"},
}


@dataclass(frozen=True)
class Fault:
    """A fault injected on the plant -> controller frames (or the controller process).

    ``kind``: drop (frames not sent), delay (sent ``delay_steps`` samples later), duplicate (sent twice), reorder (sent
    after the next sample's frames), silent (controller process frozen from ``start`` on), crash (controller process
    killed at ``start``), nan (the sample's measured outputs sent as NaN). Active for samples with
    ``start <= t < stop``, every ``every``-th one, each of those hit with ``probability`` (frame and nan faults only;
    drawn from the run's seed).
    """

    kind: str
    start: float
    stop: float
    every: int = 1
    delay_steps: int = 1
    probability: float = 1.0


@dataclass(frozen=True)
class Disturbance:
    """``value`` added to plant input ``input`` for ``start <= t < stop``."""

    input: str
    start: float
    stop: float
    value: float


DRAWN = ("parameters", "perturb", "scale")  # the plant table's entries a campaign's runs of one block may differ in


@dataclass(frozen=True)
class Scenario:
    """A parsed, checked scenario (see the module docstring for the file format)."""

    name: str
    path: Path | None
    artifact_path: Path
    plant: dict
    transport: dict
    duration: float
    mode: str = "lockstep"
    controller: str = "firmware"
    firmware: Path | None = None
    board: str = "mps2-an386"
    step_timeout: float = 0.05
    peer_timeout: float = 1.0
    period: float | None = None
    sched_fifo: bool = True
    pm_qos: bool = True
    affinity: str = "auto"
    overrun: str = "skip"
    seed: int = 0
    twin: bool = True
    model_twin: bool = True
    initial_state: dict = field(default_factory=dict)
    reference: dict = field(default_factory=dict)
    noise: dict = field(default_factory=dict)
    disturbances: tuple[Disturbance, ...] = ()
    faults: tuple[Fault, ...] = ()
    schedule_signal: dict = field(default_factory=dict)
    sigma_rate_limit: bool = True


def _num(value: Any, where: str, *, positive: bool = False, minimum: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioError(f"scenario: {where} must be a finite number, not {value!r}")
    if positive and value <= 0:
        raise ScenarioError(f"scenario: {where} must be positive")
    if minimum is not None and value < minimum:
        raise ScenarioError(f"scenario: {where} must be >= {minimum}")
    return float(value)


def _flag(data: Mapping, key: str, default: bool) -> bool:
    value = data.get(key, default)
    if not isinstance(value, bool):
        raise ScenarioError(f"scenario: {key} must be true or false, not {value!r}")
    return value


def _table(value: Any, where: str) -> dict:
    if not isinstance(value, Mapping):
        raise ScenarioError(f"scenario: {where} must be a table")
    return dict(value)


def _check_keys(d: Mapping, allowed: set[str], where: str) -> None:
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise ScenarioError(
            f"scenario: unknown key(s) {', '.join(unknown)}{did_you_mean(unknown[0], allowed)} in {where} "
            f"(allowed: {', '.join(sorted(allowed))})"
        )


def _profile(name: str, d: Any, table: str = "reference") -> dict:
    if isinstance(d, (int, float)) and not isinstance(d, bool):
        return {"kind": "constant", "value": _num(d, f"{table}.{name}")}
    d = _table(d, f"{table}.{name}")
    kind = d.get("kind")
    if kind not in PROFILE_KEYS:
        raise ScenarioError(f"scenario: {table}.{name}.kind must be one of {', '.join(PROFILE_KEYS)}")
    _check_keys(d, PROFILE_KEYS[kind] | {"kind"}, f"{table}.{name}")
    out = {"kind": kind}
    for k, v in d.items():
        if k != "kind":
            out[k] = _num(v, f"{table}.{name}.{k}")
    if kind == "sweep" and not ("low" in out and "high" in out and out.get("rate", 0.0) > 0):
        raise ScenarioError(f"scenario: {table}.{name}: a sweep needs low, high and a positive rate")
    return out


def parse_scenario(data: Mapping[str, Any], *, path: Path | None = None) -> Scenario:
    """Check a scenario mapping (as read from TOML) and return a :class:`Scenario`."""
    data = _table(data, "top level")
    _check_keys(data, TOP_KEYS, "the top level")
    base = path.parent if path is not None else Path.cwd()
    for key in ("artifact", "plant", "transport", "duration"):
        if key not in data:
            raise ScenarioError(f"scenario: missing required key {key}")
    if not isinstance(data["artifact"], str):
        raise ScenarioError("scenario: artifact must be a path string")
    art = Path(data["artifact"])
    art = art if art.is_absolute() else base / art
    mode = _choice(data, "mode", MODES, "lockstep")
    affinity = _choice(data, "affinity", AFFINITIES, "auto")
    overrun = _choice(data, "overrun", OVERRUN_POLICIES, "skip")
    controller = _choice(data, "controller", CONTROLLERS, "firmware")
    board = _choice(data, "board", BOARDS, BOARDS[0])
    if "board" in data and controller != "qemu":
        raise ScenarioError('scenario: board applies to controller = "qemu" only')
    reference = {str(k): _profile(str(k), v) for k, v in _table(data.get("reference", {}), "reference").items()}
    signals = _table(data.get("schedule_signal", {}), "schedule_signal")
    schedule_signal = {str(k): _profile(str(k), v, "schedule_signal") for k, v in signals.items()}
    noise = {str(k): _num(v, f"noise.{k}", minimum=0.0) for k, v in _table(data.get("noise", {}), "noise").items()}
    initial = {
        str(k): _num(v, f"initial_state.{k}") for k, v in _table(data.get("initial_state", {}), "initial_state").items()
    }
    period = data.get("period")
    return Scenario(
        name=str(data.get("name", path.stem if path is not None else "scenario")),
        path=path,
        artifact_path=art,
        plant=_table(data["plant"], "plant"),
        transport=_table(data["transport"], "transport"),
        duration=_num(data["duration"], "duration", positive=True),
        mode=mode,
        controller=controller,
        firmware=_firmware_path(data.get("firmware"), base),
        board=board,
        step_timeout=_num(data.get("step_timeout", 0.05), "step_timeout", positive=True),
        peer_timeout=_num(data.get("peer_timeout", 1.0), "peer_timeout", positive=True),
        period=None if period is None else _num(period, "period", positive=True),
        sched_fifo=_flag(data, "sched_fifo", True),
        pm_qos=_flag(data, "pm_qos", True),
        affinity=affinity,
        overrun=overrun,
        seed=int(_num(data.get("seed", 0), "seed")),
        twin=_flag(data, "twin", True),
        model_twin=_flag(data, "model_twin", True),
        initial_state=initial,
        reference=reference,
        noise=noise,
        disturbances=_disturbances(data),
        faults=_faults(data),
        schedule_signal=schedule_signal,
        sigma_rate_limit=_flag(data, "sigma_rate_limit", True),
    )


def _choice(data: Mapping[str, Any], key: str, allowed: tuple, default: str) -> str:
    value = data.get(key, default)
    if value not in allowed:
        raise ScenarioError(f"scenario: {key} must be one of {', '.join(allowed)}, not {value!r}")
    return value


def _firmware_path(firmware: Any, base: Path) -> Path | None:
    if firmware is None:
        return None
    if not isinstance(firmware, str):
        raise ScenarioError("scenario: firmware must be the path of a prebuilt firmware executable (qemu: ELF)")
    return Path(firmware) if Path(firmware).is_absolute() else base / firmware


def _faults(data: Mapping[str, Any]) -> tuple[Fault, ...]:
    faults = []
    for i, f in enumerate(data.get("faults", [])):
        f = _table(f, f"faults[{i}]")
        _check_keys(f, {"kind", "start", "stop", "every", "delay_steps", "probability"}, f"faults[{i}]")
        if f.get("kind") not in FAULT_KINDS:
            raise ScenarioError(f"scenario: faults[{i}].kind must be one of {', '.join(FAULT_KINDS)}")
        start = _num(f.get("start", 0.0), f"faults[{i}].start", minimum=0.0)
        stop = _num(f["stop"], f"faults[{i}].stop") if "stop" in f else 1e300
        probability = _num(f.get("probability", 1.0), f"faults[{i}].probability", minimum=0.0)
        if probability > 1.0 or ("probability" in f and f["kind"] in ("silent", "crash")):
            raise ScenarioError(f"scenario: faults[{i}].probability must be within [0, 1], on a frame fault")
        faults.append(
            Fault(
                kind=f["kind"],
                start=start,
                stop=stop,
                every=int(_num(f.get("every", 1), f"faults[{i}].every", minimum=1)),
                delay_steps=int(_num(f.get("delay_steps", 1), f"faults[{i}].delay_steps", minimum=1)),
                probability=probability,
            )
        )
    return tuple(faults)


def _disturbances(data: Mapping[str, Any]) -> tuple[Disturbance, ...]:
    dists = []
    for i, d in enumerate(data.get("disturbances", [])):
        d = _table(d, f"disturbances[{i}]")
        _check_keys(d, {"input", "start", "stop", "value"}, f"disturbances[{i}]")
        if not isinstance(d.get("input"), str):
            raise ScenarioError(f"scenario: disturbances[{i}].input must name a plant input")
        dists.append(
            Disturbance(
                input=d["input"],
                start=_num(d.get("start", 0.0), f"disturbances[{i}].start"),
                stop=_num(d.get("stop", 1e300), f"disturbances[{i}].stop"),
                value=_num(d.get("value"), f"disturbances[{i}].value"),
            )
        )
    return tuple(dists)


def builtin_scenarios() -> dict[str, Path]:
    """The built-in scenarios (``gainlink.hil`` package ``scenarios/<name>.toml``) by name: those that run an
    artifact (its ``artifact`` a placeholder the caller replaces), not the study and showcase descriptions there."""
    from importlib import resources

    folder = Path(str(resources.files("gainlink.hil").joinpath("scenarios")))
    found = {}
    for path in sorted(folder.glob("*.toml")):
        if any(line.startswith("artifact =") for line in path.read_text("utf-8").splitlines()):
            found[path.stem] = path
    return found


def resolve_scenario_path(name: str) -> Path:
    """A scenario file, or the name of a built-in one (:func:`builtin_scenarios`).

    Raises
    ------
    ScenarioError
        ``name`` is a bare name (no folder, no suffix) of neither a file nor a built-in scenario.
    """
    path = Path(name)
    if path.exists() or path.suffix or "/" in name:
        return path
    builtin = builtin_scenarios()
    if name in builtin:
        return builtin[name]
    raise ScenarioError(
        f"scenario {name} not found: no such file, nor a built-in scenario{did_you_mean(name, builtin)} "
        f"(built-in: {', '.join(builtin)})"
    )


def is_builtin_scenario(path: Path | None) -> bool:
    """Whether ``path`` is one of :func:`builtin_scenarios` (its artifact a placeholder)."""
    return path is not None and Path(path).resolve() in {p.resolve() for p in builtin_scenarios().values()}


def load_scenario(path: str | Path) -> Scenario:
    """Read and check a scenario TOML file."""
    path = Path(path)
    data, _ = read_toml(path, what="scenario", error=ScenarioError)
    return parse_scenario(data, path=path)


def profile_values(profile: Mapping[str, float], t: np.ndarray, *, base: float = 0.0) -> np.ndarray:
    """Evaluate a reference profile at times ``t``.

    References are absolute; a profile's ``initial`` (step, ramp) and ``offset`` (square, sine) default to
    ``base``, the tracked output's value at the artifact's operating point (0 without one).
    """
    kind = profile["kind"]
    if kind == "constant":
        return np.full(t.shape, profile["value"])
    if kind == "step":
        return np.where(t >= profile.get("at", 0.0), profile["value"], profile.get("initial", base))
    if kind == "square":
        phase = np.floor(2.0 * t / profile["period"]).astype(int) % 2
        return profile.get("offset", base) + profile["amplitude"] * np.where(phase == 0, 1.0, -1.0)
    if kind == "sine":
        return profile.get("offset", base) + profile["amplitude"] * np.sin(2 * np.pi * profile["frequency"] * t)
    if kind == "sweep":
        return sweep_values(profile, t)
    start, stop = profile.get("start", 0.0), profile.get("stop", np.inf)
    return profile.get("initial", base) + profile["slope"] * (np.clip(t, start, stop) - start)


def sweep_values(profile: Mapping[str, float], t: np.ndarray) -> np.ndarray:
    """A sweep across a range and back: ``low`` until ``start`` (default 0), then a ramp at ``rate`` (units per
    second, > 0) to ``high``, at once a ramp back to ``low`` at the same rate, then ``low`` (``high < low`` sweeps
    down first). Made for moving an operating point (a reference or a scheduling signal) across an envelope at a
    given speed: the campaign axes ``rate`` and ``high`` are the sigma rate and range. ``cycles`` (default 1) round
    trips, back to back."""
    low, high, rate = profile["low"], profile["high"], profile["rate"]
    span = abs(high - low)
    tau = np.clip(t - profile.get("start", 0.0), 0.0, None) * rate  # distance travelled
    tau = np.minimum(tau, 2 * span * max(profile.get("cycles", 1.0), 0.0))
    phase = np.mod(tau, 2 * span) if span > 0 else np.zeros_like(tau)
    along = np.where(phase <= span, phase, 2 * span - phase)
    return low + np.sign(high - low) * along
