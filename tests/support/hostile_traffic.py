"""Hostile traffic for the hostile-traffic tests: run as a separate process beside a HIL run.

    python tests/support/hostile_traffic.py can --group G --port P --count N [--rate R] [--seed S]
                                            --meas-lo ID --meas-hi ID --base-id ID
    python tests/support/hostile_traffic.py mavlink --target HOST:PORT --count N [--rate R] [--seed S] --frames FILE

Prints one JSON line at the end: ``{"sent": N, "by_kind": {...}, "seconds": T}``. Every datagram is sent once;
``--rate`` (datagrams/s, 0 = as fast as possible) paces them; with ``--bursts`` they go out in bursts of the
size the caller asks for on stdin (``go N``), between the steps of a run.

CAN (python-can udp_multicast wire format, packed with python-can's own packer and then mutated): every
datagram is built so that the firmware must refuse it (not a flat msgpack map of a standard data frame),
filter it (a well-formed frame with an identifier outside the measurement range) or find it too short (a
measurement identifier with fewer bytes than its values) — none may be taken as a sample. The CAN link has
no authentication (neither has a CAN bus): its defence is to take only well-formed frames of its own ids.

MAVLink: ``--frames`` names a file of hex lines, each one datagram the caller prepared (signed with a wrong
key, unsigned, replays of frames already accepted, ...); this sends them and random mutations of them
(bit flips, truncations, concatenations, garbage), in a seeded random order.
"""

from __future__ import annotations

import argparse
import json
import random
import socket
import struct
import sys
import time

import msgpack

CAN_KINDS = (
    "mutated",
    "foreign_id",
    "extended",
    "remote",
    "error_frame",
    "classic_too_long",
    "oversized",
    "container_bomb",
    "not_a_map",
    "garbage",
    "short_measurement",
)


def _pack(
    arbitration_id: int,
    data: bytes,
    *,
    fd: bool = False,
    extended: bool = False,
    remote: bool = False,
    error: bool = False,
) -> bytes:
    import can
    from can.interfaces.udp_multicast.utils import pack_message

    return pack_message(
        can.Message(
            arbitration_id=arbitration_id,
            data=data,
            is_fd=fd,
            is_extended_id=extended,
            is_remote_frame=remote,
            is_error_frame=error,
            timestamp=time.time(),
            check=False,
        )
    )


def _could_be_sample(datagram: bytes, lo: int, hi: int) -> bool:
    """True when a datagram might decode to a frame of the layout (ids ``lo..hi``): then it is not sent."""
    unpacker = msgpack.Unpacker(raw=False, strict_map_key=False)
    unpacker.feed(datagram)
    try:
        obj = next(unpacker)  # the first object only: the firmware ignores trailing bytes too
    except Exception:
        return False
    if not isinstance(obj, dict):
        return False
    ident = obj.get("arbitration_id")
    return isinstance(ident, int) and lo <= ident <= hi


def can_datagram(kind: str, rng: random.Random, *, lo: int, hi: int, base: int) -> bytes:
    """One hostile udp_multicast datagram of ``kind`` (see CAN_KINDS); ``base..hi`` is the whole layout."""
    foreign = rng.choice([rng.randint(0, base - 1) if base > 0 else hi + 1, rng.randint(hi + 1, 0x7FF)])
    payload = bytes(rng.getrandbits(8) for _ in range(rng.choice([8, 8, 12, 64])))
    if kind == "foreign_id":
        return _pack(foreign, payload[:8])
    if kind == "extended":
        return _pack(rng.randint(lo, hi), payload[:8], extended=True)
    if kind == "remote":
        return _pack(rng.randint(lo, hi), b"", remote=True)
    if kind == "error_frame":
        return _pack(rng.randint(lo, hi), payload[:8], error=True)
    if kind == "classic_too_long":
        return msgpack.packb(
            {
                "arbitration_id": rng.randint(lo, hi),
                "is_extended_id": False,
                "is_fd": False,
                "dlc": 12,
                "data": payload[:12].ljust(12, b"\0"),
            },
            use_bin_type=True,
        )
    if kind == "oversized":
        return msgpack.packb(
            {"arbitration_id": rng.randint(lo, hi), "data": bytes(8), "pad": bytes(400)}, use_bin_type=True
        )
    if kind == "container_bomb":
        return rng.choice(
            [
                bytes.fromhex("dfffffffff"),
                bytes.fromhex("dd7fffffff"),
                b"\x81\xa4data\xdd\x00\xff\xff\xff",
                b"\x81\xa1x\x91\x91\x91\x91\x90",
            ]
        )
    if kind == "not_a_map":
        return msgpack.packb([rng.randint(lo, hi), payload[:8]], use_bin_type=True)
    if kind == "garbage":
        return bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 200)))
    if kind == "short_measurement":
        return _pack(rng.randint(lo, hi), payload[: rng.randint(0, 3)])
    # mutated: a well-formed frame of a foreign id, then bit flips / truncation / extension
    base = bytearray(_pack(foreign, payload[:8], fd=rng.random() < 0.5))
    for _ in range(rng.randint(1, 4)):
        op = rng.random()
        if op < 0.6 and base:
            base[rng.randrange(len(base))] ^= 1 << rng.randrange(8)
        elif op < 0.8 and len(base) > 1:
            del base[rng.randrange(1, len(base)) :]
        else:
            base += bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 16)))
    return bytes(base)


def can_datagrams(count: int, seed: int, *, lo: int, hi: int, base: int) -> tuple[list[bytes], dict[str, int]]:
    """``count`` hostile CAN datagrams: none can be taken as a frame of the layout (measurement ids ``lo..hi``,
    command ids from ``base``) with enough bytes, so neither end may act on one."""
    rng = random.Random(seed)
    out, by_kind = [], dict.fromkeys(CAN_KINDS, 0)
    templates: dict[str, list[bytes]] = {}
    while len(out) < count:
        kind = rng.choice(CAN_KINDS)
        pool = templates.setdefault(kind, [])
        if len(pool) < 64:  # python-can's packer is slow: mutate from a pool of a few per kind
            d = can_datagram(kind, rng, lo=lo, hi=hi, base=base)
            pool.append(d)
        else:
            d = bytearray(rng.choice(pool))
            if kind in ("mutated", "garbage") and d:
                d[rng.randrange(len(d))] ^= 1 << rng.randrange(8)
            d = bytes(d)
        if kind == "mutated" and _could_be_sample(d, base, hi):
            continue
        out.append(d)
        by_kind[kind] += 1
    return out, by_kind


MAVLINK_KINDS = ("as_prepared", "bitflip", "truncated", "concatenated", "garbage")


def mavlink_datagrams(frames_file: str, count: int, seed: int) -> tuple[list[bytes], dict[str, int]]:
    """``count`` datagrams: the prepared frames (hex lines of ``frames_file``) as they are and mutated."""
    rng = random.Random(seed)
    with open(frames_file, encoding="ascii") as fh:
        frames = [bytes.fromhex(line) for line in fh.read().split()]
    out, by_kind = [], dict.fromkeys(MAVLINK_KINDS, 0)
    for _ in range(count):
        kind = rng.choice(MAVLINK_KINDS)
        d = bytearray(rng.choice(frames))
        if kind == "bitflip":
            for _ in range(rng.randint(1, 3)):
                d[rng.randrange(len(d))] ^= 1 << rng.randrange(8)
        elif kind == "truncated":
            del d[rng.randrange(1, len(d)) :]
        elif kind == "concatenated":
            d += rng.choice(frames)[: rng.randint(1, 64)]
        elif kind == "garbage":
            d = bytearray(rng.getrandbits(8) for _ in range(rng.randint(1, 280)))
        out.append(bytes(d))
        by_kind[kind] += 1
    return out, by_kind


def send_all(sock: socket.socket, dest: tuple[str, int], datagrams: list[bytes], *, rate: float) -> float:
    """Send each datagram once, paced at ``rate`` per second (0: as fast as the socket takes them)."""
    t0 = time.perf_counter()
    for i, d in enumerate(datagrams):
        if rate > 0:
            due = t0 + i / rate
            while time.perf_counter() < due:
                time.sleep(max(0.0, min(0.002, due - time.perf_counter())))
        while True:
            try:
                sock.sendto(d, dest)
                break
            except (BlockingIOError, ENOBUFS_ERRORS):
                time.sleep(0.0005)
    return time.perf_counter() - t0


ENOBUFS_ERRORS = OSError  # sendto of a datagram can fail with ENOBUFS under load; it is retried, not lost


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="send hostile datagrams")
    sub = ap.add_subparsers(dest="kind", required=True)
    c = sub.add_parser("can")
    c.add_argument("--group", required=True)
    c.add_argument("--port", type=int, required=True)
    c.add_argument("--meas-lo", type=lambda s: int(s, 0), required=True)
    c.add_argument("--meas-hi", type=lambda s: int(s, 0), required=True)
    c.add_argument("--base-id", type=lambda s: int(s, 0), required=True)
    m = sub.add_parser("mavlink")
    m.add_argument("--target", required=True)
    m.add_argument("--frames", required=True)
    for p in (c, m):
        p.add_argument("--count", type=int, required=True)
        p.add_argument("--rate", type=float, default=0.0)
        p.add_argument("--seed", type=int, default=1)
        p.add_argument("--delay", type=float, default=0.0, help="seconds to wait before sending")
        p.add_argument(
            "--bursts",
            action="store_true",
            help="print 'ready' once the datagrams are made, then for "
            "each line 'go N' on stdin send the next N and print 'sent N'",
        )
    args = ap.parse_args(argv)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
    if args.kind == "can":
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("b", 0))
        datagrams, by_kind = can_datagrams(args.count, args.seed, lo=args.meas_lo, hi=args.meas_hi, base=args.base_id)
        dest = (args.group, args.port)
    else:
        host, port = args.target.rsplit(":", 1)
        datagrams, by_kind = mavlink_datagrams(args.frames, args.count, args.seed)
        dest = (host, int(port))
    if args.bursts:
        print("ready", flush=True)
        at, seconds = 0, 0.0
        while at < len(datagrams):
            words = sys.stdin.readline().split()
            if len(words) != 2 or words[0] != "go":
                break
            chunk = datagrams[at : at + int(words[1])]
            seconds += send_all(sock, dest, chunk, rate=args.rate)
            at += len(chunk)
            print(f"sent {len(chunk)}", flush=True)
        datagrams = datagrams[:at]
    else:
        time.sleep(args.delay)
        seconds = send_all(sock, dest, datagrams, rate=args.rate)
    print(json.dumps({"sent": len(datagrams), "by_kind": by_kind, "seconds": round(seconds, 3)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
