"""libFuzzer harnesses of the firmware decoders and the gain commit path: built with ASan/UBSan, seeded from
valid traffic made here, each run briefly (bench/fuzz.py runs them for millions of executions)."""

from __future__ import annotations

import subprocess

import pytest
from gainlink.firmware import fuzz
from gainlink.shipping import artifact as artifact_mod

pytestmark = pytest.mark.slow  # started first (tests/conftest.py)

# Per harness: the suite's share, a smoke run (bench/fuzz.py does the long runs). A count, not a time: a timed run
# does less work the busier the machine; 100k inputs reach the edge coverage (cov 54-324) that 5 s reached.
RUNS = 100_000


@pytest.fixture(scope="module")
def harnesses(pend):
    artifact = artifact_mod.load(pend)
    return artifact, fuzz.build_harnesses(artifact)


@pytest.mark.parametrize("name", fuzz.HARNESSES)
def test_seed_corpus_is_valid_traffic(harnesses, name, tmp_path):
    """Seeds from the real senders reach the accepting paths: more coverage than an empty corpus."""
    artifact, exes = harnesses
    assert fuzz.write_seeds(name, artifact, tmp_path / "seeds") >= 4
    seeded = fuzz.run(name, exes[name], tmp_path / "seeds", runs=0, artifacts=tmp_path / "crashes")
    empty = fuzz.run(name, exes[name], tmp_path / "empty", runs=0, artifacts=tmp_path / "crashes")
    assert seeded.crashes == () and seeded.exit_code == 0
    assert seeded.cov > empty.cov


@pytest.mark.parametrize("name", fuzz.HARNESSES)
def test_short_fuzz_run_finds_nothing(harnesses, name, tmp_path):
    artifact, exes = harnesses
    fuzz.write_seeds(name, artifact, tmp_path / "corpus")
    r = fuzz.run(name, exes[name], tmp_path / "corpus", runs=RUNS, artifacts=tmp_path / "crashes")
    reproducers = {p: open(p, "rb").read()[:64].hex() for p in r.crashes}
    assert r.crashes == () and r.exit_code == 0, f"libFuzzer found inputs that fail: {reproducers}"
    assert r.executions == RUNS  # it ran to the end
    assert r.corpus > 4  # and found inputs of its own beyond the seeds


def test_msgpack_container_bombs_are_refused_without_allocating(harnesses, tmp_path):
    """A 5-byte map32 header declaring 2^32 entries made msgpack-c ask for 256 GiB (found by this harness);
    nested or huge containers are now refused before unpacking."""
    _, exes = harnesses
    bombs = [bytes.fromhex("dfffffffff"), bytes.fromhex("dd7fffffff"), bytes.fromhex("81a164dd00ffffff")]
    for i, bomb in enumerate(bombs):
        path = tmp_path / f"bomb{i}"
        path.write_bytes(bomb)
        proc = subprocess.run(
            [str(exes["can_udp"]), "-rss_limit_mb=256", str(path)], capture_output=True, text=True, timeout=60
        )
        assert proc.returncode == 0, proc.stderr[-400:]


def test_can_layout_seeds_cover_every_field_of_both_headers(pend, tmp_path):
    """The CAN layout harness's corpus has frames of both headers of wire format 4 (docs/design.md) with every field
    set: classic (4 bytes: byte 2 the flags' bits 0-7, byte 3 the saturation nibble and the flags' bits 8-11) and CAN
    FD (8 bytes: bytes 2-3 the flags, bytes 4-7 the saturation bits), each with CAPPED (0x100) and every value's
    saturation bit, both encodings. A seed is ``[config (bit 0 int16, bit 1 FD), length - 1, frame index] + payload``
    (fuzz_can_layout.c)."""
    import struct

    a = artifact_mod.load(pend)
    k = a.p + a.q  # 3 values: one FD frame; classic frames of 1 float32 or 2 int16 values
    n = fuzz.write_seeds("can_layout", a, tmp_path / "seeds")
    seeds = [(tmp_path / "seeds" / f"seed-{i:03d}").read_bytes() for i in range(n)]
    covered = set()
    for seed in seeds:
        config, count, index, data = seed[0], seed[1] + 1, seed[2], seed[3:]
        assert count == k
        fd, int16 = bool(config & 2), bool(config & 1)
        if fd:
            _, status, sat = struct.unpack_from("<HHI", data)
            values = k
        else:
            _, status, byte3 = struct.unpack_from("<HBB", data)
            status, sat = status | (byte3 >> 4) << 8, byte3 & 0x0F
            values = min(2 if int16 else 1, k - index * (2 if int16 else 1))
        if status & 0x100 and sat == (1 << values) - 1:
            covered.add((fd, int16))
    assert covered == {(fd, int16) for fd in (False, True) for int16 in (False, True)}
