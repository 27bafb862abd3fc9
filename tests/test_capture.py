"""Bounded capture of a child's stderr: drained at once (the child never blocks), head and tail kept, the rest
counted; what was written before a read is seen by it."""

from __future__ import annotations

import os
import subprocess
import sys

from gainlink.firmware.capture import HEAD_BYTES, TAIL_BYTES, StderrCapture

CHILD = """
import sys
for i in range(40000):
    sys.stderr.write(f"line {i:06d} " + "x" * 40 + "\\n")
sys.stderr.write("steps=7 read=9 dropped=0x10 refused=2\\n")
sys.stderr.flush()
print("done", flush=True)
sys.stdin.readline()
"""


def test_a_flood_on_stderr_is_drained_and_kept_bounded():
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    cap = StderrCapture(proc.stderr)
    assert proc.stdout.readline() == b"done\n"  # it got past 2 MB of stderr: the pipe never stayed full
    seen_while_running = cap.text()  # written before the read: it is there
    proc.stdin.write(b"\n")
    proc.stdin.flush()
    proc.wait(timeout=10)
    cap.join()
    total = 40000 * 53 + len("steps=7 read=9 dropped=0x10 refused=2\n")
    assert cap.total_bytes == total
    assert cap.dropped_bytes == total - HEAD_BYTES - TAIL_BYTES
    text = cap.text()
    assert text.startswith("line 000000") and "bytes not kept" in text and len(text) < HEAD_BYTES + TAIL_BYTES + 100
    assert "steps=7 read=9 dropped=0x10 refused=2" in seen_while_running
    assert cap.counters() == {"steps": 7, "read": 9, "dropped": 16, "refused": 2}
    proc.stdin.close()
    proc.stdout.close()


def test_an_exit_summary_across_the_head_tail_boundary_is_read_whole():
    """A summary line that starts in the kept head and ends in the tail (nothing left out between them) is one
    line: its counters all come back (the hostile-traffic test once saw only the summary's last 100 bytes)."""
    summary = "samples=20000 commits=0 " + " ".join(f"counter_{i}=1" for i in range(30)) + " crc32=0x10\n"
    lead = "e" * 60 + "\n"
    count = (HEAD_BYTES - len(summary) // 2) // len(lead)  # the summary begins before HEAD_BYTES, ends after
    child = f"import sys\nsys.stderr.write({lead!r} * {count} + {summary!r})\n"
    proc = subprocess.run([sys.executable, "-c", child], stderr=subprocess.PIPE, timeout=30)
    assert proc.returncode == 0
    r, w = os.pipe()
    with open(w, "wb") as out:
        out.write(proc.stderr)
    cap = StderrCapture(open(r, "rb"))
    cap.join()
    assert cap.total_bytes > HEAD_BYTES > cap.total_bytes - len(summary) and cap.dropped_bytes == 0
    got = cap.counters()
    assert got["samples"] == 20000 and got["crc32"] == 16 and len(got) == 33
