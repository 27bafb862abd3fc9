"""Bounded capture of a child process's stderr (the firmware apps, HIL controller peers).

A thread drains the pipe as fast as the child writes, so the child never blocks on it, and keeps only the
first ``head`` and the last ``tail`` bytes: a peer flooded with hostile traffic (or a long soak) cannot grow
the parent's memory or a temporary file without bound. What was not kept is counted.
"""

from __future__ import annotations

import os
import re
import select
import threading
import time
from typing import IO

HEAD_BYTES = 8 * 1024
TAIL_BYTES = 56 * 1024
_COUNTER = re.compile(r"\b([a-z_0-9]+)=(0x[0-9a-fA-F]+|-?\d+)\b")


class StderrCapture:
    """Drain ``stream`` (a pipe's read end) in a daemon thread, keeping its head and tail.

    Parameters
    ----------
    stream : binary file
        The pipe to read (``Popen(..., stderr=subprocess.PIPE).stderr``); closed when it ends.
    head, tail : int
        Bytes kept from the start and from the end.
    """

    def __init__(self, stream: IO[bytes], *, head: int = HEAD_BYTES, tail: int = TAIL_BYTES) -> None:
        self._stream = stream
        self._head_cap, self._tail_cap = head, tail
        self._head = bytearray()
        self._tail = bytearray()
        self._lock = threading.Lock()
        self.total_bytes = 0
        self._reading = threading.Lock()
        self._thread = threading.Thread(target=self._drain, name="stderr-capture", daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        fd = self._stream.fileno()
        try:
            while True:
                select.select([fd], [], [])  # wait without the lock; read only while holding it
                with self._reading:
                    chunk = os.read(fd, 65536)
                    if not chunk:
                        break
                    self._keep(chunk)
        except (OSError, ValueError):
            pass
        finally:
            try:
                self._stream.close()
            except OSError:
                pass

    def _keep(self, chunk: bytes) -> None:
        with self._lock:
            self.total_bytes += len(chunk)
            room = self._head_cap - len(self._head)
            if room > 0:
                self._head += chunk[:room]
                chunk = chunk[room:]
            self._tail += chunk
            if len(self._tail) > self._tail_cap:
                del self._tail[: len(self._tail) - self._tail_cap]

    @property
    def dropped_bytes(self) -> int:
        """Bytes read but not kept (between the head and the tail)."""
        with self._lock:
            return self.total_bytes - len(self._head) - len(self._tail)

    def join(self, timeout: float = 2.0) -> None:
        """Wait until the stream ended (call after the process exited) so its last lines are here."""
        self._thread.join(timeout)

    def _settle(self, limit: float = 0.5) -> None:
        """Wait (briefly) until what the child wrote so far is read and kept, so callers see it.

        Bytes leave the pipe only under ``_reading``: holding it and finding the pipe empty means every byte
        written before this call is kept.
        """
        deadline = time.monotonic() + limit
        while self._thread.is_alive() and time.monotonic() < deadline:
            with self._reading:
                try:
                    pending = bool(select.select([self._stream.fileno()], [], [], 0)[0])
                except (OSError, ValueError):
                    return
            if not pending:
                return
            time.sleep(0.001)

    def text(self) -> str:
        """What was kept, with a marker where bytes were left out."""
        self._settle()
        with self._lock:
            head, tail = bytes(self._head), bytes(self._tail)
            gap = self.total_bytes - len(head) - len(tail)
        middle = f"\n[... {gap} bytes not kept ...]\n".encode() if gap else b""
        return (head + middle + tail).decode(errors="replace").strip()

    def tail_lines(self, lines: int = 3) -> list[str]:
        """The last complete lines kept."""
        self._settle()
        with self._lock:
            head, tail = bytes(self._head), bytes(self._tail)
            gap = self.total_bytes - len(head) - len(tail)
        # Head and tail are one stream until bytes are left out between them (a line may cross the boundary);
        # after a gap the tail's first line may start in the middle: not a complete line.
        data = head + tail if gap == 0 else tail.partition(b"\n")[2]
        return [t.strip() for t in data.decode(errors="replace").strip().splitlines()[-lines:]]

    def counters(self) -> dict[str, int]:
        """``key=value`` integers of the last line that has any (the apps' exit summary), else ``{}``."""
        for line in reversed(self.tail_lines(8)):
            found = _COUNTER.findall(line)
            if len(found) >= 3:
                return {k: int(v, 0) for k, v in found}
        return {}
