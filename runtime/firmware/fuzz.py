"""libFuzzer harnesses of the firmware: build (clang, ASan + UBSan), seed corpora from valid traffic, runs.

The harness sources live in ``firmware/fuzz/`` (one ``LLVMFuzzerTestOneInput`` each, with oracles of their
own besides the sanitizers); they are built per artifact, like every firmware build, under
``.cache/firmware/`` with ``GL_FUZZ=ON``. Seed corpora are never committed: :func:`write_seeds` makes them
from traffic the real senders produce for the artifact (cantools-encoded CAN frames packed by python-can's
``udp_multicast`` packer, the artifact's own gain set as the C struct and as PARAM_SET edits).
:func:`run` runs one harness for a time or a number of executions and reads libFuzzer's final statistics.
"""

from __future__ import annotations

import re
import shutil
import struct
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ToolchainError
from ..shipping import gains_layout
from ..shipping.artifact import Artifact
from ..shipping.law_c import refuse
from .build import build

HARNESSES = ("can_udp", "can_layout", "gains_stage", "mavlink_node") + (
    ("slcan",) if (Path(__file__).resolve().parents[2] / "firmware" / "apps" / "can" / "gl_slcan.c").is_file() else ()
)
"""Harness names; the executable of ``NAME`` is ``fuzz/fuzz_NAME`` in the fuzz build (``slcan`` where the firmware
has the slcan adapter)."""

CAN_LAYOUT_VALUES = 32
"""The longest vector the CAN layout harness decodes (fuzz_can_layout.c's MAX_VALUES)."""

MAX_LEN = 4096
"""Largest input libFuzzer generates (the largest seed, a whole gain set, is a few hundred bytes)."""


@dataclass(frozen=True)
class FuzzRun:
    """Outcome of one libFuzzer run.

    Attributes
    ----------
    harness : str
        Harness name.
    executions : int
        Inputs executed (libFuzzer's ``number_of_executed_units``).
    seconds : float
        Wall time of the run.
    cov : int
        Coverage points (edges) reached, libFuzzer's ``cov:``.
    ft : int
        Features (edge, counter-bucket and comparison features), libFuzzer's ``ft:``.
    corpus : int
        Inputs in the corpus at the end.
    crashes : tuple of str
        Paths of the crash, leak, timeout or out-of-memory reproducers written (empty when none).
    exit_code : int
        libFuzzer's exit status (0 when nothing was found).
    """

    harness: str
    executions: int
    seconds: float
    cov: int
    ft: int
    corpus: int
    crashes: tuple[str, ...]
    exit_code: int

    @property
    def exec_per_s(self) -> float:
        """Executions per second of wall time."""
        return self.executions / self.seconds if self.seconds > 0 else 0.0


def clang() -> str:
    """Path of clang, or :class:`ToolchainError` naming the package."""
    path = shutil.which("clang")
    if path is None:
        raise ToolchainError("clang not found: install clang (make setup) to build the fuzz harnesses")
    return path


def harnesses_of(artifact: Artifact) -> tuple[str, ...]:
    """The harnesses built for ``artifact``'s law: ``gains_stage`` stages the observer-based law's ``gl_gains_t``,
    which an MPC image does not have (its tables, ``gl_mpc_set_t``, are staged by the MAVLink node's harness)."""
    from ..shipping.law_c import law_name

    return tuple(h for h in HARNESSES if not (h == "gains_stage" and law_name(artifact) == "mpc/float32"))


def build_harnesses(artifact: Artifact) -> dict[str, Path]:
    """Build (cached) every harness for ``artifact``; returns name -> executable.

    Raises
    ------
    ToolchainError
        clang is missing or the build failed.
    """
    refuse(artifact, "fuzz", what="fuzzing")
    result = build(artifact, target="host", options={"GL_FUZZ": "ON", "CMAKE_C_COMPILER": clang()})
    exes = {name: result.build_dir / "fuzz" / f"fuzz_{name}" for name in harnesses_of(artifact)}
    missing = [str(p) for p in exes.values() if not p.is_file()]
    if missing:
        raise ToolchainError(f"fuzz build did not produce {', '.join(missing)}")
    return exes


def _can_frames(artifact: Artifact) -> list[tuple[bool, str, int, bytes]]:
    """(fd, encoding, index, payload) of measurement frames as the bridge sends them, both encodings, classic and
    FD; one sample more has every header field set (every flag of the table, every value's saturation bit), so the
    corpus covers each header's fields (wire format 4: the FD header's 16 status and 32 saturation bits)."""
    from gainlink.shipping.can_layout import layout_for
    from gainlink.shipping.flags import FLAGS

    rng = np.random.default_rng(7)
    names = [*artifact.signals["outputs"], *artifact.signals["references"]]
    ranges = {name: [-5.0, 5.0] for name in names}
    every_flag = sum(f.bit for f in FLAGS)
    out = []
    for fd in (False, True):
        for encoding in ("float32", "int16"):
            layout = layout_for(artifact, fd=fd, encoding=encoding, ranges=ranges)
            db = layout.database()
            for seq in (0, 1, 2, 65535):
                values = rng.uniform(-4.0, 4.0, artifact.p + artifact.q)
                if seq == 65535:
                    values[0] = np.nan  # the fault path: a NaN sample (raw -32768 in int16)
                for index, spec in enumerate(layout.measurement):
                    flags = every_flag if seq == 2 else 0
                    sat = (1 << len(spec.signals)) - 1 if seq == 2 else 0
                    hi = (flags >> 8) & ((1 << spec.header.status_hi_bits) - 1)
                    signals = {"seq": seq, "status": flags & 0xFF, "sat": sat, "status_hi": hi}
                    for i, name in enumerate(spec.signals):
                        v = float(values[spec.first + i])
                        # the DBC's int16 signals name raw -32768 "not_a_number"; float32 carries NaN itself
                        signals[name] = "not_a_number" if np.isnan(v) and encoding == "int16" else v
                    data = db.encode_message(spec.arbitration_id, signals, scaling=True, strict=False)
                    out.append((fd, encoding, index, bytes(data)))
    return out


def _seeds_can_udp(artifact: Artifact) -> list[bytes]:
    import can
    from can.interfaces.udp_multicast.utils import pack_message

    seeds = []
    for fd, _enc, index, data in _can_frames(artifact):
        msg = can.Message(
            arbitration_id=0x110 + index, data=data, is_fd=fd, is_extended_id=False, timestamp=1.0 + index
        )
        seeds.append(pack_message(msg))
    return seeds


def _seeds_can_layout(artifact: Artifact) -> list[bytes]:
    count = artifact.p + artifact.q
    seeds = []
    for fd, enc, index, data in _can_frames(artifact):
        config = (1 if enc == "int16" else 0) | (2 if fd else 0)
        seeds.append(bytes([config, (count - 1) % CAN_LAYOUT_VALUES, index]) + data)
    return seeds


def gains_struct(artifact: Artifact) -> bytes:
    """The artifact's ``gl_gains_t`` as the C struct lays it out on a little-endian host (CRC included)."""
    from ..shipping.codegen import gain_set, shape_of

    return gains_layout.GAINS.pack(shape_of(artifact), gain_set(artifact).fields)


def _seeds_gains_stage(artifact: Artifact) -> list[bytes]:
    from ..shipping.codegen import shape_of

    raw = gains_struct(artifact)
    seeds = [bytes([1]) + raw, bytes([3]) + raw]  # the compiled set as sent, and sealed again
    places = gains_layout.GAINS.offsets(shape_of(artifact))
    k_first = (places["K"][0] - places["Ts"][0]) // 4  # the harness's edits index floats from Ts
    k = np.frombuffer(raw, dtype="<f4", count=places["K"][1] // 4, offset=places["K"][0])
    retune = b"".join(struct.pack("<Hf", k_first + i, float(v) * 1.1) for i, v in enumerate(k))
    seeds += [bytes([0]) + retune, bytes([2]) + retune]  # a retune as PARAM_SETs: unsealed, then committed
    return seeds


FUZZ_KEY = bytes(range(1, 33))
"""The signing key of the MAVLink harness's keyed node (fuzz_mavlink_node.c: 0x01 0x02 .. 0x20)."""


def _retune_commit(artifact: Artifact) -> tuple[str, float, float]:
    """(param id, new value, GL_HASH value) of a one-gain retune and its commit, as an uploader sends them.

    The new value is chosen so the CRC's four bytes, read as a float32, are not a NaN pattern (which a round
    trip through a Python float could alter): the commit goes out exactly as a bytewise INT32.
    """
    from ..shipping.codegen import gain_set, payload_crc32

    g = gain_set(artifact)
    base = float(np.asarray(g.fields["K"]).ravel()[0])
    for factor in (1.1, 1.2, 1.3, 1.4):
        fields = {k: np.array(v, dtype=np.float32, copy=True) for k, v in g.fields.items()}
        fields["K"].reshape(-1)[0] = np.float32(base * factor)
        crc = payload_crc32(header=g.header, fields=fields)
        (as_float,) = struct.unpack("<f", struct.pack("<I", crc))
        if not np.isnan(as_float):
            return "GL_K_0_0", float(np.float32(base * factor)), as_float
    raise ToolchainError("no retune with a non-NaN CRC pattern found")  # 4 tries: (255/256)^4 odds


def _mavlink_frames(artifact: Artifact, *, signed: bool) -> list[bytes]:
    """One frame of each kind a ground station, an uploader and the HIL bridge send to the node."""
    from pymavlink.dialects.v20 import common as mavlink2

    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    if signed:
        mav.signing.secret_key = FUZZ_KEY
        mav.signing.sign_outgoing = True
        mav.signing.link_id = 1
        mav.signing.timestamp = 1
    name, value, commit = _retune_commit(artifact)
    sample = [0.01 * (i + 1) for i in range(artifact.p + artifact.q)] + [0.0] * (58 - artifact.p - artifact.q)
    msgs = [
        mavlink2.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3),
        mavlink2.MAVLink_param_request_list_message(1, 1),
        mavlink2.MAVLink_param_request_read_message(1, 1, b"GL_TS", -1),
        mavlink2.MAVLink_param_request_read_message(1, 1, b"", 3),
        mavlink2.MAVLink_param_set_message(1, 1, name.encode(), value, mavlink2.MAV_PARAM_TYPE_REAL32),
        mavlink2.MAVLink_param_set_message(1, 1, b"GL_HASH", commit, mavlink2.MAV_PARAM_TYPE_INT32),
        mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_PREFLIGHT_STORAGE, 0, 1, 0, 0, 0, 0, 0, 0),
        mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_PREFLIGHT_STORAGE, 0, 0, 0, 0, 0, 0, 0, 0),
        mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_PREFLIGHT_STORAGE, 0, 2, 0, 0, 0, 0, 0, 0),
        mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0),
        mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_REQUEST_MESSAGE, 0, 1, 0, 0, 0, 0, 0, 0),
        mavlink2.MAVLink_debug_float_array_message(1000, b"GL_SAMPLE", 1, sample),
        mavlink2.MAVLink_debug_float_array_message(2000, b"GL_RESET", 2, [0.0] * 58),
        mavlink2.MAVLink_debug_float_array_message(3000, b"GL_IDLE", 3, [0.0] * 58),
        mavlink2.MAVLink_setup_signing_message(1, 1, list(bytes(range(101, 133))), 5),
    ]
    return [bytes(m.pack(mav)) for m in msgs]


def _seeds_mavlink_node(artifact: Artifact) -> list[bytes]:
    seeds = []
    # mode byte (fuzz_mavlink_node.c): bit 0 keyed, bit 1 trusted link, bit 2 datagram link (unkeyed; else serial)
    for mode, signed in ((0, False), (1, True), (2, False), (4, False), (6, False)):
        frames = _mavlink_frames(artifact, signed=signed)
        seeds += [bytes([mode, 0]) + f for f in frames]
        whole = b"".join(frames[:6] + frames[6:7] + frames[11:12])  # an upload: set, commit, persist, then a step
        seeds.append(bytes([mode, len(frames[0]) + 3]) + whole)
    return seeds


def _seeds_slcan(artifact: Artifact) -> list[bytes]:
    """Lawicel lines a host sends an adapter: set-up, the layout's classic frames (both encodings), queries."""
    lines = [b"S6\r", b"O\r", b"V\r", b"N\r", b"F\r", b"Z0\r", b"C\r", b"L\r", b"T0000011F2AABB\r", b"r1108\r"]
    frames = [
        f"t{0x110 + index:03X}{len(data):d}{data.hex().upper()}\r".encode()
        for fd, _enc, index, data in _can_frames(artifact)
        if not fd
    ]
    seeds = [bytes([0]) + line for line in lines]
    seeds += [bytes([2]) + b"O\r" + f for f in frames]  # split inside the first frame's line
    seeds.append(bytes([5]) + b"S6\rO\r" + b"".join(frames[:4]) + b"C\r")
    return seeds


_SEEDS = {
    "slcan": _seeds_slcan,
    "can_udp": _seeds_can_udp,
    "can_layout": _seeds_can_layout,
    "gains_stage": _seeds_gains_stage,
    "mavlink_node": _seeds_mavlink_node,
}


def write_seeds(harness: str, artifact: Artifact, directory: Path) -> int:
    """Write the seed corpus of ``harness`` for ``artifact`` into ``directory``; returns the number of seeds."""
    if harness not in _SEEDS:
        raise ToolchainError(f"unknown fuzz harness {harness!r} (choose from {', '.join(HARNESSES)})")
    directory.mkdir(parents=True, exist_ok=True)
    seeds = _SEEDS[harness](artifact)
    for i, seed in enumerate(seeds):
        (directory / f"seed-{i:03d}").write_bytes(seed)
    return len(seeds)


_STAT = re.compile(r"^stat::(\w+):\s+(\d+)", re.M)
_PROGRESS = re.compile(r"cov: (\d+) ft: (\d+) corp: (\d+)/")


def run(
    harness: str,
    exe: Path,
    corpus: Path,
    *,
    seconds: float | None = None,
    runs: int | None = None,
    artifacts: Path,
    extra: tuple[str, ...] = (),
) -> FuzzRun:
    """Run one harness on ``corpus`` (which grows) for ``seconds`` or ``runs`` executions.

    Parameters
    ----------
    harness : str
        Its name (for the result).
    exe : Path
        The harness executable.
    corpus : Path
        Corpus directory (seeds; new inputs are added).
    seconds, runs : optional
        Stop after this wall time or this many executions (at least one of them; ``runs=0`` only replays the
        corpus).
    artifacts : Path
        Where crash reproducers are written.
    extra : tuple of str
        More libFuzzer flags.

    Returns
    -------
    FuzzRun
    """
    if seconds is None and runs is None:
        raise ToolchainError("fuzz run needs a time or an execution limit")
    artifacts.mkdir(parents=True, exist_ok=True)
    corpus.mkdir(parents=True, exist_ok=True)
    before = set(artifacts.iterdir())
    argv = _libfuzzer_argv(exe, corpus, seconds=seconds, runs=runs, artifacts=artifacts, extra=extra)
    t0 = time.perf_counter()
    proc = subprocess.run(
        argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, errors="replace"
    )
    elapsed = time.perf_counter() - t0
    crashes = tuple(sorted(str(p) for p in set(artifacts.iterdir()) - before))
    if proc.returncode != 0 and not crashes and "stat::" not in proc.stderr:
        tail = proc.stderr.strip().splitlines()[-1:] or ["no output"]
        raise ToolchainError(f"fuzz harness {harness} failed to run (exit {proc.returncode}): {tail[0][:200]}")
    return _fuzz_run(harness, proc.stderr, seconds=elapsed, crashes=crashes, exit_code=proc.returncode)


def _libfuzzer_argv(
    exe: Path, corpus: Path, *, seconds: float | None, runs: int | None, artifacts: Path, extra: tuple[str, ...]
) -> list[str]:
    """The harness's command line: libFuzzer's limits, reproducers into ``artifacts``, final statistics printed."""
    argv = [
        str(exe),
        f"-max_len={MAX_LEN}",
        "-timeout=10",
        "-rss_limit_mb=2048",
        "-print_final_stats=1",
        f"-artifact_prefix={artifacts}/",
    ]
    if seconds is not None:
        argv.append(f"-max_total_time={max(1, int(round(seconds)))}")
    if runs is not None:
        argv.append(f"-runs={runs}")
    return argv + [*extra, str(corpus)]


def _fuzz_run(harness: str, stderr: str, *, seconds: float, crashes: tuple[str, ...], exit_code: int) -> FuzzRun:
    """The run's outcome from libFuzzer's output: executions from the final statistics, coverage, features and
    corpus size from the last progress line."""
    stats = {k: int(v) for k, v in _STAT.findall(stderr)}
    progress = _PROGRESS.findall(stderr)
    cov, ft, corp = (int(x) for x in progress[-1]) if progress else (0, 0, 0)
    return FuzzRun(
        harness=harness,
        executions=stats.get("number_of_executed_units", 0),
        seconds=seconds,
        cov=cov,
        ft=ft,
        corpus=corp,
        crashes=crashes,
        exit_code=exit_code,
    )
