"""A run's liveness: a file in its run directory that the training loop refreshes between
iterations and while it is paused, and the check a supervisor runs (`paramimic health RUN_DIR`,
the compose healthcheck): the run's lock is held and the file is recent. A learner hung inside
an iteration, or a run directory that does not exist, fails the check."""

from __future__ import annotations

import fcntl
import os
import time
from pathlib import Path

HEARTBEAT = "heartbeat"
LOCK_FILE = ".lock"  # held (flock) by the learner that owns the run directory
EVERY = 5.0  # s: the file is rewritten at most this often


def beat(run_dir: Path) -> None:
    """Refresh the liveness file (atomically: a reader never sees half of it). On a full disk
    the file's time is touched instead (that needs no space; `problem` reads the later of the
    two)."""
    path = Path(run_dir) / HEARTBEAT
    try:
        if time.time() - path.stat().st_mtime < EVERY:
            return
    except FileNotFoundError:
        pass
    tmp = path.with_name(f".{HEARTBEAT}-{os.getpid()}")
    try:
        tmp.write_text(f"{time.time():.3f}\n")
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)
        if path.exists():
            os.utime(path)


def problem(run_dir: Path, max_age: float) -> str | None:
    """Why the run at `run_dir` is not alive, or None: no run directory, its lock free (no
    learner owns it), or a liveness file older than `max_age` seconds (a hung learner)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        return f"no run directory at {run_dir}"
    lock = run_dir / LOCK_FILE
    if not lock.exists():
        return f"no learner owns {run_dir} (no {LOCK_FILE})"
    with open(lock, "a") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pass  # held: a learner owns the run
        else:
            fcntl.flock(f, fcntl.LOCK_UN)
            return f"no learner owns {run_dir} (its lock is free)"
    path = run_dir / HEARTBEAT
    try:
        age = time.time() - max(float(path.read_text()), path.stat().st_mtime)
    except (OSError, ValueError):
        return f"{run_dir} has no liveness file yet"
    if age > max_age:
        return f"the learner of {run_dir} has not moved for {age:.0f} s (limit {max_age:.0f} s)"
    return None
