"""Child processes and ports of the launcher."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def port_is_free(host: str, port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
        return True


def stop_process(process: subprocess.Popen | None, timeout: float = 10.0) -> None:
    """SIGTERM, then SIGKILL if it has not exited within `timeout` seconds."""
    if process is None or process.poll() is not None:
        return
    process.send_signal(signal.SIGTERM)
    try:
        process.wait(timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


PDEATH = Path(__file__).with_name("pdeath.py")


def dying_with_parent(command: list[str], sig: int = signal.SIGTERM) -> list[str]:
    """`command` wrapped so that the child gets `sig` when this process dies, even by SIGKILL
    (Linux PR_SET_PDEATHSIG, armed by `pdeath.py` before it execs the command), so that no
    embedded Redis or API outlives its launcher. SIGTERM lets Redis fsync its AOF on the way
    out. Unlike a `preexec_fn`, safe in a process with threads."""
    return [sys.executable, "-I", str(PDEATH), str(os.getpid()), str(int(sig)), *command]
