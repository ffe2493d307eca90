"""What the learner tells Redis: run metadata, progress, the per-iteration history and events;
and what it reads back: the run's control requests (pause, resume, k) made through the API."""

from __future__ import annotations

import time
from pathlib import Path

from paramimic.characters import registration
from paramimic.config import ExperimentConfig
from services.keys import HISTORY_LIMIT, RUNS, RunKeys
from services.store import add_event, connect, dumps, finite

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


class RunReporter:
    def __init__(self, redis_url: str, run_id: str, retry_seconds: float = 120.0) -> None:
        self.keys = RunKeys(run_id)
        self.redis = connect(redis_url, retry_seconds)
        self.restarts_seen = 0

    def start(
        self, cfg: ExperimentConfig, run_dir: Path, total_steps: int, api_url: str | None
    ) -> None:
        """Register the run (or mark a resumed one running again)."""
        keys, now = self.keys, time.time()
        resumed = bool(self.redis.exists(keys.meta))
        pipe = self.redis.pipeline(transaction=True)
        meta = {
            "name": cfg.name,
            "character": cfg.character,
            "character_info": dumps(registration(cfg.character).info()),
            "config": dumps(cfg.model_dump(mode="json")),
            "status": "running",
            "run_dir": str(run_dir.resolve()),
            "total_steps": total_steps,
            "api_url": api_url or "",
            "updated_at": now,
        }
        if not resumed:
            meta["started_at"] = now
            pipe.zadd(RUNS, {keys.run_id: now})
        pipe.hset(keys.meta, mapping=meta)
        pipe.hset(keys.control, "paused", 0)
        pipe.hdel(keys.control, "k")
        kind = "run_resumed" if resumed else "run_started"
        add_event(pipe, keys, kind, f"{cfg.name}: training {'resumed' if resumed else 'started'}")
        pipe.execute()

    def progress(self, m: dict) -> None:
        """Progress and one history record per iteration, in one transaction. A resumed run
        overwrites the records after its checkpoint."""
        keys, it = self.keys, int(m["iteration"])
        record = finite(m)  # JSON has no NaN/inf: they become null
        fields = {k: dumps(record.get(k)) for k in PROGRESS_FIELDS}
        fields["updated_at"] = dumps(time.time())
        pipe = self.redis.pipeline(transaction=True)
        pipe.hset(keys.progress, mapping=fields)
        pipe.hset(keys.meta, "updated_at", time.time())
        pipe.zremrangebyscore(keys.history, it, "+inf")
        pipe.zadd(keys.history, {dumps(record): it})
        pipe.zremrangebyrank(keys.history, 0, -HISTORY_LIMIT - 1)
        restarts = int(m.get("actor_restarts", 0))
        if restarts > self.restarts_seen:
            add_event(
                pipe,
                keys,
                "actor_restarted",
                f"{restarts - self.restarts_seen} rollout actor(s) restarted; "
                f"{m.get('dropped_fragments', 0)} fragment(s) dropped so far",
                {"iteration": it, "actor_restarts": restarts},
            )
            self.restarts_seen = restarts
        pipe.execute()

    def event(self, kind: str, message: str, data: dict | None = None) -> None:
        add_event(self.redis, self.keys, kind, message, data)

    def set_status(self, status: str, message: str | None = None) -> None:
        pipe = self.redis.pipeline(transaction=True)
        pipe.hset(self.keys.meta, mapping={"status": status, "updated_at": time.time()})
        if message:
            add_event(pipe, self.keys, f"run_{status}", message)
        pipe.execute()

    def take_control(self) -> tuple[bool, float | None]:
        """(paused, requested k or None); a k request is consumed by reading it."""
        pipe = self.redis.pipeline(transaction=True)
        pipe.hmget(self.keys.control, ["paused", "k"])
        pipe.hdel(self.keys.control, "k")
        (paused, k), _ = pipe.execute()
        return paused == "1", None if k is None else float(k)
