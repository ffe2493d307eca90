"""`paramimic health RUN_DIR`, the learner's healthcheck: alive only while a learner holds the
run's lock and keeps refreshing its liveness file; a missing run directory, a free lock or a
learner that stopped moving (hung inside an iteration) fail it."""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import time

from conftest import compose_learner_health, wait_until

from services.launch.liveness import HEARTBEAT, LOCK_FILE, beat


def _health(run_dir, max_age=600):
    return subprocess.run(
        [sys.executable, "-m", "services.cli", "health", str(run_dir), "--max-age", str(max_age)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip


@contextlib.contextmanager
def _holding(lock):
    """Another process holding `lock` (flock) as a learner's launcher does, until the block
    ends."""
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, sys, time; f = open(sys.argv[1], 'a'); "
         "fcntl.flock(f, fcntl.LOCK_EX); print('held', flush=True); time.sleep(600)",
         str(lock)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        yield
    finally:
        holder.kill()
        holder.wait()


def test_health_fails_unless_a_learner_holds_the_run_and_moves(tmp_path):
    run = tmp_path / "run"
    res = _health(run)
    assert res.returncode == 1 and "no run directory" in res.stdout
    run.mkdir()
    (run / LOCK_FILE).touch()
    res = _health(run)
    assert res.returncode == 1 and "its lock is free" in res.stdout
    with _holding(run / LOCK_FILE):  # a learner: holds the lock as the launcher does
        assert "no liveness file" in _health(run).stdout
        beat(run)
        res = _health(run)
        assert res.returncode == 0 and "alive" in res.stdout
        stale = time.time() - 900
        (run / HEARTBEAT).write_text(f"{stale}\n")  # a learner hung for 15 minutes: the
        os.utime(run / HEARTBEAT, (stale, stale))  # file neither rewritten nor touched since
        res = _health(run, max_age=600)
        assert res.returncode == 1 and re.search("has not moved for 9[0-9][0-9] s", res.stdout)
    wait_until(lambda: _health(run).returncode == 1, 30, "the lock to be free again")


def test_the_compose_healthcheck_runs_this_check(tmp_path):
    """deploy/docker-compose.yml's learner healthcheck command itself, in a shell: it fails on a
    missing run directory, on a free lock and on a learner that stopped moving, and passes
    on one that holds the run and moves."""
    run = tmp_path / "compose"
    res = compose_learner_health(run, 600)
    assert res.returncode == 1 and "no run directory" in res.stdout, res.stdout + res.stderr
    run.mkdir()
    (run / LOCK_FILE).touch()
    assert compose_learner_health(run, 600).returncode == 1
    with _holding(run / LOCK_FILE):
        beat(run)
        res = compose_learner_health(run, 600)
        assert res.returncode == 0, res.stdout + res.stderr
        stale = time.time() - 900
        (run / HEARTBEAT).write_text(f"{stale}\n")
        os.utime(run / HEARTBEAT, (stale, stale))
        res = compose_learner_health(run, 600)
        assert res.returncode == 1 and re.search("has not moved for 9[0-9][0-9] s", res.stdout)
