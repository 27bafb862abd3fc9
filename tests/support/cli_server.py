"""The ``gainlink`` console script's commands run by one process that has imported gainlink's command line and the
libraries its commands import (python-control, SciPy, matplotlib) once, forking a copy of itself for each command.

A page of the docs runs up to a dozen ``gainlink`` commands as its reader types them, each a process that imports
python-control (2.6 CPU-s: SciPy's signal module parses its docstrings on import) before a few milliseconds of
design. ``tests/test_docs.py`` puts a ``gainlink`` of its own first on the blocks' PATH: a small client that hands
its command line, folder, environment, standard streams and network namespace to the server and exits with the
command's status; the signals it receives (SIGINT, SIGTERM, SIGHUP) are passed on to the command, and the command
is killed if the client is. The command runs as the console script runs it (:func:`gainlink.cli.main` without
arguments: the process is the command) in a fork of the server: the same code on the same arguments, files and
streams, without the imports.

Run as a script: ``python cli_server.py SOCKET`` serves until SIGTERM (it prints ``ready`` once it listens), then
waits for the commands it started, so that their CPU time is counted as its children's.
"""

from __future__ import annotations

import array
import contextlib
import ctypes
import io
import json
import os
import select
import signal
import socket
import sys
import traceback
from pathlib import Path

CLONE_NEWNET = 0x40000000
FDS = 4  # the client's stdin, stdout, stderr and network namespace

#: The client: the interpreter's quickest start (-IS: isolated, no site packages), the standard library only.
CLIENT = """\
import array, json, os, signal, socket, sys
request = json.dumps({"argv": sys.argv[1:], "cwd": os.getcwd(), "env": dict(os.environ)}).encode()
fds = array.array("i", [0, 1, 2, os.open("/proc/self/ns/net", os.O_RDONLY)])
with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
    conn.connect(%(socket)r)
    conn.sendmsg([len(request).to_bytes(4, "big")], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, fds)])
    conn.sendall(request)
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # passed on to the command
        signal.signal(signum, lambda signum, _: conn.send(bytes([signum])))
    reply = b""
    while chunk := conn.recv(16):
        reply += chunk
sys.exit(int(reply) if reply else 1)
"""


def write_client(path: Path, sock: Path) -> None:
    """An executable ``gainlink`` at ``path`` that runs its command line in the server listening at ``sock``."""
    path.write_text(f"#!{sys.executable} -IS\n" + CLIENT % {"socket": str(sock)})
    path.chmod(0o755)


def _preload() -> None:
    """What the commands import, imported once here: the design side's libraries and every command module."""
    import control  # noqa: F401
    import gainlink.api  # noqa: F401
    from gainlink.cli import build_parser

    build_parser()


def _receive(conn: socket.socket) -> tuple[dict, list[int]]:
    """The client's request and its file descriptors."""
    fds = array.array("i")
    data, ancdata, _, _ = conn.recvmsg(4, socket.CMSG_SPACE(FDS * fds.itemsize))
    for level, kind, payload in ancdata:
        if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
            fds.frombytes(payload[: len(payload) - len(payload) % fds.itemsize])
    size, body = int.from_bytes(data, "big"), b""
    while len(body) < size:
        chunk = conn.recv(size - len(body))
        if not chunk:
            raise EOFError("the client left before its request was read")
        body += chunk
    return json.loads(body), list(fds)


def _enter_network(fd: int) -> None:
    """Join the client's network namespace (a page's block runs in one of its own) when it is not this one."""
    if os.fstat(fd).st_ino == os.stat("/proc/self/ns/net").st_ino:
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.setns(fd, CLONE_NEWNET) != 0:
        raise OSError(ctypes.get_errno(), "setns into the client's network namespace")


def _streams(unbuffered: bool) -> None:
    """sys.stdin/stdout/stderr on the descriptors 0-2, buffered as a fresh interpreter's are on pipes."""
    buffering = 0 if unbuffered else -1
    encoding = sys.stdout.encoding
    sys.stdin = io.TextIOWrapper(open(0, "rb", closefd=False), encoding=encoding)
    sys.stdout = io.TextIOWrapper(open(1, "wb", buffering=buffering, closefd=False), encoding=encoding,
                                  write_through=unbuffered)  # fmt: skip
    sys.stderr = io.TextIOWrapper(open(2, "wb", buffering=buffering, closefd=False), encoding=encoding,
                                  errors="backslashreplace", line_buffering=True, write_through=unbuffered)  # fmt: skip


def _become(request: dict, fds: list[int]) -> None:
    """This process takes the client's place: its network namespace, streams, folder, environment and command
    line, with a fresh interpreter's signal dispositions."""
    _enter_network(fds[3])
    for target, fd in enumerate(fds[:3]):
        os.dup2(fd, target)
    for fd in fds:
        os.close(fd)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    _streams(bool(os.environ.get("PYTHONUNBUFFERED")))
    sys.argv = ["gainlink", *request["argv"]]


def _command(request: dict, fds: list[int]) -> int:
    """Run the request in this (forked) process as the console script would; its exit status."""
    import atexit

    from gainlink.cli import main

    _become(request, fds)
    try:
        code = main()
    except SystemExit as exc:  # argparse's usage errors and --help; a message when the code is not a status
        code = exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 1
        if exc.code is not None and not isinstance(exc.code, int):
            print(exc.code, file=sys.stderr)
    except BaseException:  # a defect: its traceback, status 1, as the interpreter would
        traceback.print_exc()
        code = 1
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    return code


def _serve_one(conn: socket.socket) -> None:
    """In a child of the server: fork the command, pass on the signals the client receives (Ctrl-C, a timeout's
    SIGTERM) and kill it if the client is gone, wait for it, send its exit status (a shell's 128 + N when a signal N
    ended it)."""
    request, fds = _receive(conn)
    pid = os.fork()
    if pid == 0:
        conn.close()
        os._exit(_command(request, fds))
    for fd in fds:
        os.close(fd)
    done = os.pidfd_open(pid)
    while done not in select.select([conn, done], [], [])[0]:
        sent = conn.recv(16)
        if not sent:  # the client is gone (killed): so is its command
            os.kill(pid, signal.SIGKILL)
            break
        for signum in sent:
            os.kill(pid, signum)
    os.close(done)
    code = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
    with contextlib.suppress(OSError):  # a client that is gone
        conn.sendall(str(code if code >= 0 else 128 - code).encode())


def _stop(_signum: int, _frame: object) -> None:
    raise SystemExit(0)


def _reap(block: bool) -> None:
    """Wait for finished children (all of them when ``block``): their CPU time then counts as this process's
    children's, as a command run directly would count as the suite's."""
    while True:
        try:
            pid, _ = os.waitpid(-1, 0 if block else os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return


def serve(sock: Path) -> None:
    """Listen at ``sock`` and run each connection's command in a fork, until SIGTERM."""
    _preload()
    signal.signal(signal.SIGTERM, _stop)
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
            server.bind(str(sock))
            server.listen(16)
            print("ready", flush=True)
            while True:
                conn, _ = server.accept()
                if os.fork() == 0:
                    signal.signal(signal.SIGTERM, signal.SIG_DFL)
                    server.close()
                    try:
                        _serve_one(conn)
                    finally:
                        os._exit(0)
                conn.close()
                _reap(block=False)
    finally:
        _reap(block=True)


if __name__ == "__main__":
    serve(Path(sys.argv[1]))
