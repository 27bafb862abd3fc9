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
