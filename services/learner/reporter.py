"""What the learner tells Redis: run metadata, progress, the per-iteration history and events;
and what it reads back: the run's control requests (pause, resume, k) made through the API."""

from __future__ import annotations

import os
import secrets
import socket
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from paramimic.characters import registration
from paramimic.config import ExperimentConfig
from services.keys import HISTORY_LIMIT, LEASE_SECONDS, RUNS, RunKeys
from services.store import LeaseLost, add_event, connect, dumps, finite

PROGRESS_FIELDS = (
    "iteration",
    "env_steps",
    "episodes_total",
    "steps_per_second",
    "mean_return",
    "fall_percent",
    "actors",
    "nodes",
)


class RunOwned(RuntimeError):
    """Another learner holds the run's lease."""


# renew the lease only if it is still ours (another learner may have taken an expired one)
_RENEW = "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('expire', KEYS[1], ARGV[2]) else return 0 end"  # noqa: E501
_RELEASE = "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('del', KEYS[1]) else return 0 end"  # noqa: E501


def _process_start(pid: int) -> str | None:
    """A process's identity beyond its pid: this boot's id and the process's start time in
    clock ticks (/proc; None where there is no /proc). A restarted container's learner is pid
    1 with the same hostname again, but started at another time."""
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()[:8]
        stat = Path(f"/proc/{pid}/stat").read_text()
        return f"{boot}.{stat.rsplit(')', 1)[1].split()[19]}"  # field 22: starttime
    except (OSError, IndexError):
        return None


def _dead_here(owner: str) -> bool:
    """Whether a lease owner 'host:pid:start:nonce' (or 'host:pid:nonce' of older releases) was
    a process of this machine that is gone: no such pid, or a pid now another process's."""
    host, pid, *rest = owner.split(":")
    if host != socket.gethostname() or not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # alive, another user's
        return False
    if len(rest) == 2:  # this release's owners say when their process started
        started = _process_start(int(pid))
        return started is not None and started != rest[0]
    return False


class RunReporter:
    def __init__(self, redis_url: str, run_id: str, retry_seconds: float = 120.0) -> None:
        self.keys = RunKeys(run_id)
        self.redis = connect(redis_url, retry_seconds)
        self.restarts_seen = 0
        # the owner string is also the fencing token: every write is conditioned on the lease
        # still holding it, and a learner that takes the lease over has another one
        started = _process_start(os.getpid()) or "0"
        self.owner = f"{socket.gethostname()}:{os.getpid()}:{started}:{secrets.token_hex(4)}"
        self._heartbeat: threading.Event | None = None
        self.lease_seconds = LEASE_SECONDS
        self._renewed = 0.0  # time.monotonic() of the last renewal that returned ours
        self._lost = False

    def acquire(self, lease_seconds: int = LEASE_SECONDS) -> None:
        """Own the run: its lease key, set only if no live learner holds it, renewed every
        lease/3 s by a daemon thread until `release()`. RunOwned if another learner has it."""
        if self._heartbeat is not None:
            return
        for _ in range(2):
            if self.redis.set(self.keys.lease, self.owner, nx=True, ex=lease_seconds):
                break
            holder = self.redis.get(self.keys.lease) or ""
            if _dead_here(holder):  # a learner of this machine killed without releasing
                self.redis.eval(_RELEASE, 1, self.keys.lease, holder)
                continue
            ttl = self.redis.ttl(self.keys.lease)
            raise RunOwned(
                f"run {self.keys.run_id} is being trained by another learner ({holder}); its "
                f"lease expires {ttl} s after that learner stops"
            )
        else:
            raise RunOwned(f"run {self.keys.run_id}: could not take its lease")
        self.lease_seconds, self._renewed, self._lost = lease_seconds, time.monotonic(), False
        stop = self._heartbeat = threading.Event()

        def beat() -> None:
            while not stop.wait(lease_seconds / 3):
                try:
                    ours = self.redis.eval(_RENEW, 1, self.keys.lease, self.owner, lease_seconds)
                except Exception:  # Redis away: `holds` stops the writes past the deadline
                    continue
                if ours:
                    self._renewed = time.monotonic()
                else:  # expired and taken, or deleted: never ours again
                    self._lost = True

        threading.Thread(target=beat, name="run-lease", daemon=True).start()

    def holds(self) -> bool:
        """Whether this learner may still write the run (Kubernetes' leader-election rule): its
        last renewal is younger than 2/3 of the lease. Past that, or if the lease was found
        taken, it may take the lease back only if nobody else did meanwhile (it lapsed during a
        Redis outage); otherwise it stops."""
        if self._heartbeat is None:
            return False
        if not self._lost and time.monotonic() - self._renewed < self.lease_seconds * 2 / 3:
            return True
        if self._lost:
            return False
        try:
            if self.redis.set(self.keys.lease, self.owner, nx=True, ex=self.lease_seconds) or (
                self.redis.eval(_RENEW, 1, self.keys.lease, self.owner, self.lease_seconds)
            ):
                self._renewed = time.monotonic()
                return True
        except Exception:
            return False
        self._lost = True
        return False

    def _write(self, ops) -> None:
        """`ops(pipe)` in one transaction that runs only while the lease holds this learner's
        token (WATCH the lease, check it, MULTI): a learner that lost its lease writes nothing."""

        def transaction(pipe) -> None:
            if pipe.get(self.keys.lease) != self.owner:
                self._lost = True
                raise LeaseLost(f"run {self.keys.run_id}: the lease is no longer this learner's")
            pipe.multi()
            ops(pipe)

        self.redis.transaction(transaction, self.keys.lease)

    def release(self) -> None:
        if self._heartbeat is not None:
            self._heartbeat.set()
            self._heartbeat = None
            self.redis.eval(_RELEASE, 1, self.keys.lease, self.owner)

    def start(
        self, cfg: ExperimentConfig, run_dir: Path, total_steps: int, api_url: str | None
    ) -> None:
        """Own the run (`acquire`) and register it (or mark a resumed one running again)."""
        self.acquire()
        keys, now = self.keys, time.time()
        resumed = bool(self.redis.exists(keys.meta))
        meta = {
            "name": cfg.name,
            "character": cfg.character,
            "character_info": dumps(registration(cfg.character).info()),
            "config": dumps(cfg.model_dump(mode="json")),
            "parameters": dumps(cfg.parameters()),
            "status": "running",
            "run_dir": str(run_dir.resolve()),
            "total_steps": total_steps,
            "api_url": api_url or "",
            "updated_at": now,
        }
        kind = "run_resumed" if resumed else "run_started"

        def ops(pipe) -> None:
            if not resumed:
                meta["started_at"] = now
                pipe.zadd(RUNS, {keys.run_id: now})
            pipe.hset(keys.meta, mapping=meta)
            pipe.hset(keys.control, "paused", 0)
            pipe.hdel(keys.control, "k")
            message = f"{cfg.name}: training {'resumed' if resumed else 'started'}"
            add_event(pipe, keys, kind, message)

        self._write(ops)

    def progress(self, m: dict, episode_ids: Sequence[str] = ()) -> None:
        """Progress and one history record per iteration, in one transaction. A resumed run
        overwrites the records after its checkpoint. `episode_ids`: the episodes this iteration
        learned from, added to the run's learned set (and counted, so a duplicate shows)."""
        keys, it = self.keys, int(m["iteration"])
        record = finite(m)  # JSON has no NaN/inf: they become null
        fields = {k: dumps(record.get(k)) for k in PROGRESS_FIELDS}
        fields["updated_at"] = dumps(time.time())
        restarts = int(m.get("actor_restarts", 0))

        def ops(pipe) -> None:
            pipe.hset(keys.progress, mapping=fields)
            pipe.hset(keys.meta, "updated_at", time.time())
            pipe.zremrangebyscore(keys.history, it, "+inf")
            pipe.zadd(keys.history, {dumps(record): it})
            pipe.zremrangebyrank(keys.history, 0, -HISTORY_LIMIT - 1)
            if episode_ids:
                pipe.sadd(keys.learned, *episode_ids)
                pipe.hincrby(keys.meta, "learned_episodes", len(episode_ids))
            if restarts > self.restarts_seen:
                add_event(
                    pipe,
                    keys,
                    "actor_restarted",
                    f"{restarts - self.restarts_seen} rollout actor(s) restarted; "
                    f"{m.get('dropped_fragments', 0)} fragment(s) dropped so far",
                    {"iteration": it, "actor_restarts": restarts},
                )

        self._write(ops)
        self.restarts_seen = max(self.restarts_seen, restarts)

    def event(self, kind: str, message: str, data: dict | None = None) -> None:
        self._write(lambda pipe: add_event(pipe, self.keys, kind, message, data))

    def set_status(self, status: str, message: str | None = None) -> None:
        def ops(pipe) -> None:
            pipe.hset(self.keys.meta, mapping={"status": status, "updated_at": time.time()})
            if message:
                add_event(pipe, self.keys, f"run_{status}", message)

        self._write(ops)

    def take_control(self) -> tuple[bool, float | None]:
        """(paused, requested k or None); a k request is consumed by reading it."""
        pipe = self.redis.pipeline(transaction=True)
        pipe.hmget(self.keys.control, ["paused", "k"])
        pipe.hdel(self.keys.control, "k")
        (paused, k), _ = pipe.execute()
        return paused == "1", None if k is None else float(k)
