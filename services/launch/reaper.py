"""A watchdog that outlives the launcher: if the launcher dies without cleaning up (SIGKILL, OOM),
it ends every process the launcher had started — including the ones that do not die with their
parent on their own, such as a local Ray's agents — so that nothing is left behind.

    python -m services.launch.reaper LAUNCHER_PID

It reads /proc once a second (Linux): the launcher's descendants, each with its start time (so a
reused pid is never killed). When the launcher is gone, it sends SIGTERM to those still alive,
then SIGKILL after a grace period, and exits. A launcher that exits normally stops it first.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

POLL = 1.0
GRACE = 5.0


def _stat(pid: int) -> tuple[int, int] | None:
    """(parent pid, start time) of a process, None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()
    return int(fields[1]), int(fields[19])


def descendants(root: int) -> dict[int, int]:
    """pid -> start time of every descendant of `root` now."""
    children: dict[int, list[int]] = {}
    starts: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            st = _stat(int(entry))
            if st is not None:
                children.setdefault(st[0], []).append(int(entry))
                starts[int(entry)] = st[1]
    out, todo = {}, list(children.get(root, []))
    while todo:
        pid = todo.pop()
        if pid in starts and pid not in out:
            out[pid] = starts[pid]
            todo += children.get(pid, [])
    return out


def alive(pid: int, start: int) -> bool:
    st = _stat(pid)
    return st is not None and st[1] == start


def watch(launcher: int) -> None:
    me = os.getpid()
    first = _stat(launcher)
    if first is None:
        return
    known: dict[int, int] = {}
    while alive(launcher, first[1]):
        known.update(descendants(launcher))
        known.pop(me, None)
        time.sleep(POLL)
    left = {p: s for p, s in known.items() if p != me and alive(p, s)}
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in left:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)
        deadline = time.monotonic() + GRACE
        while time.monotonic() < deadline and any(alive(p, s) for p, s in left.items()):
            time.sleep(0.2)
        left = {p: s for p, s in left.items() if alive(p, s)}
        if not left:
            return


def start() -> subprocess.Popen:
    """Start the watchdog for this process (it survives us: its own session, no PDEATHSIG)."""
    return subprocess.Popen(
        [sys.executable, "-m", "services.launch.reaper", str(os.getpid())],
        start_new_session=True,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


if __name__ == "__main__":
    watch(int(sys.argv[1]))
