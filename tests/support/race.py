"""A second ground station that resets a gainlink node at the worst moment: between the commit an uploader sees
echoed and the confirmation it asks for next (two ground stations on one vehicle, the race made deterministic).

The uploader talks to the node through this relay (``udpout:`` to :attr:`ResetAfterCommit.url`). When the node's
echo of ``GL_HASH`` carrying ``crc`` passes on its way back, the relay first sends the node, from a socket of its
own (another ground station, system 250), ``MAV_CMD_PREFLIGHT_STORAGE`` param1 = 2 (back to the compiled set) and
waits for its COMMAND_ACK; only then does the echo reach the uploader.
"""

from __future__ import annotations

import selectors
import socket
import struct
import threading

from gainlink.mavlink.params import HASH_ID
from pymavlink.dialects.v20 import common as mavlink2


class ResetAfterCommit:
    """The relay thread (a context manager); ``reset_result`` is the node's COMMAND_ACK result once it reset."""

    def __init__(self, *, node_port: int, crc: int):
        self.node = ("127.0.0.1", node_port)
        self.crc = crc & 0xFFFFFFFF
        self.front = _udp()
        self.back = _udp()
        self.other_gcs = _udp()
        self.other_gcs.settimeout(5.0)
        self.url = f"udpout:127.0.0.1:{self.front.getsockname()[1]}"
        self.reset_result: int | None = None
        self._client: tuple[str, int] | None = None
        self._parser = mavlink2.MAVLink(None)
        self._parser.robust_parsing = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="reset-after-commit", daemon=True)

    def _is_the_commit_echo(self, data: bytes) -> bool:
        for m in self._parser.parse_buffer(bytearray(data)) or []:
            if m.get_type() == "PARAM_VALUE" and m.param_id == HASH_ID:
                raw = bytes(m.get_msgbuf())[10:14]  # param_value: the first payload field, bytewise int32
                if struct.unpack("<I", raw)[0] == self.crc:
                    return True
        return False

    def _reset_the_node(self) -> None:
        gcs = mavlink2.MAVLink(None, srcSystem=250, srcComponent=mavlink2.MAV_COMP_ID_MISSIONPLANNER)
        cmd = mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_PREFLIGHT_STORAGE, 0, 2, 0, 0, 0, 0, 0, 0)
        self.other_gcs.sendto(cmd.pack(gcs), self.node)
        while self.reset_result is None:
            data, _ = self.other_gcs.recvfrom(65536)
            for m in gcs.parse_buffer(bytearray(data)) or []:
                if m.get_type() == "COMMAND_ACK" and m.command == mavlink2.MAV_CMD_PREFLIGHT_STORAGE:
                    self.reset_result = int(m.result)

    def _run(self) -> None:
        with selectors.DefaultSelector() as sel:
            sel.register(self.front, selectors.EVENT_READ, "up")
            sel.register(self.back, selectors.EVENT_READ, "down")
            while not self._stop.is_set():
                for key, _ in sel.select(timeout=0.05):
                    data, addr = key.fileobj.recvfrom(65536)
                    if key.data == "up":
                        self._client = addr
                        self.back.sendto(data, self.node)
                        continue
                    if self.reset_result is None and self._is_the_commit_echo(data):
                        self._reset_the_node()
                    if self._client is not None:
                        self.front.sendto(data, self._client)

    def __enter__(self) -> ResetAfterCommit:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        for s in (self.front, self.back, self.other_gcs):
            s.close()


def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s
