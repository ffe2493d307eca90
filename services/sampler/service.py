"""The sampler: paramimic's curriculum with its state in Redis.

Every call that changes the curriculum writes what changed in one MULTI/EXEC transaction before
it returns, so an acknowledged change is in Redis (and, with AOF `appendfsync everysec`, on disk
within a second). A sampler that starts again reloads that state and continues exactly where it
was. After any (re)connection to Redis the next transaction rewrites the whole state, so a server
that restarted and lost its last second of writes is brought up to date.

Episode ingestion is idempotent by episode id (Ray retries calls at least once): ids already in
the run's `seen` set are skipped, and the new ids are added in the same transaction as the
counters they change.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections import deque
from collections.abc import Iterable

import numpy as np

from paramimic.config import ExperimentConfig
from paramimic.messages import CurriculumSummary, EpisodeReport, TaskDeal
from paramimic.rl.numpy_mlp import Layers
from paramimic.training.method import method_for
from services.keys import SAMPLES_LIMIT, RunKeys
from services.store import LeaseLost, add_event, connect, dumps

RECENT_IDS = 4096  # ids re-added on a full rewrite (a restarted Redis may have lost the last ones)
GRID_SIZE = 21  # points per display dimension of the V̄ and density snapshots


class SamplerService:
    def __init__(
        self,
        config: dict,
        redis_url: str,
        run_id: str,
        restarted: bool = False,
        retry_seconds: float = 120.0,
        clip: dict | None = None,
        owner: str | None = None,
    ) -> None:
        # `clip`: the [L21] clip's trace shape and a0 (`Spaces.clip_setup` of the run's method);
        # `owner`: the learner's lease token: each write runs only while the lease holds it
        self.owner = owner
        cfg = ExperimentConfig.model_validate(config)
        self.curriculum = method_for(cfg).new_curriculum(clip)
        self.parts = self.curriculum.STATE_PARTS
        self.entry_parts = self.curriculum.ENTRY_PARTS  # each in a hash of its own
        self.keys = RunKeys(run_id)
        self.recent_ids: deque[str] = deque(maxlen=RECENT_IDS)
        self.rewrite_all = True
        self.redis = connect(redis_url, retry_seconds, on_connect=self._reconnected)
        fields = [p for p in self.parts if p not in self.entry_parts]
        stored = self.redis.hmget(self.keys.curriculum, fields)
        if all(v is not None for v in stored):  # a restart: continue where it was
            state = {p: json.loads(v) for p, v in zip(fields, stored, strict=True)}
            for part in self.entry_parts:
                entries = self.redis.hgetall(self.keys.part(part))
                state[part] = {k: json.loads(v) for k, v in entries.items()}
            self.curriculum.from_state(state)
            kind = "sampler_restarted" if restarted else "sampler_started"
            self._commit(self.parts, event=(kind, "sampler reloaded its state from Redis"))
        else:
            self._commit(self.parts, event=("sampler_started", "sampler started fresh"))

    def _reconnected(self) -> None:
        self.rewrite_all = True

    def _commit(
        self,
        parts: Iterable[str],
        ops=None,
        event: tuple[str, str] | None = None,
    ) -> None:
        """Write `parts` of the state (all of it after a reconnection), the public summary and
        `ops(pipe)` in one transaction."""
        for attempt in range(2):
            full = self.rewrite_all
            self.rewrite_all = False
            wanted = self.parts if full else tuple(parts)
            state = self.curriculum.to_state([p for p in wanted if p not in self.entry_parts])
            fields = {p: dumps(v) for p, v in state.items()}
            fields["summary"] = dumps(self.curriculum.summary().to_dict())
            fields["updated_at"] = f"{time.time():.3f}"
            views = self.curriculum.views(wanted, GRID_SIZE)
            fields |= {name: dumps(view) for name, view in views.items()}
            entries = {part: self._entries(part, full) for part in self.entry_parts}
            digest = self.digest() if event is not None else None

            def write(
                pipe, full=full, fields=fields, entries=entries, ops=ops, event=event, digest=digest
            ):
                if self.owner is not None:  # fenced: only while the learner holds the lease
                    if pipe.get(self.keys.lease) != self.owner:
                        raise LeaseLost(f"run {self.keys.run_id}: the learner's lease is gone")
                    pipe.multi()
                for part, (added, removed) in entries.items():
                    self._write_entries(pipe, part, full, added, removed)
                pipe.hset(self.keys.curriculum, mapping=fields)
                if full and self.recent_ids:
                    pipe.sadd(self.keys.seen, *self.recent_ids)
                if ops is not None:
                    ops(pipe)
                if event is not None:
                    add_event(pipe, self.keys, event[0], event[1], {"digest": digest})

            if self.owner is None:
                pipe = self.redis.pipeline(transaction=True)
                write(pipe)
                pipe.execute()
            else:
                self.redis.transaction(write, self.keys.lease)
            if not self.rewrite_all or attempt:
                return
            # the connection was re-established during execute: write the whole state once more
            # (`ops` and the event were applied already)
            ops, event = None, None

    def _entries(self, part: str, full: bool) -> tuple[dict, list]:
        """(added, removed) of an entry-by-entry part since the last write: all of it on a
        full rewrite."""
        added, removed = self.curriculum.drain(part)
        return (self.curriculum.entries(part), []) if full else (added, removed)

    def _write_entries(self, pipe, part: str, full: bool, added: dict, removed: list) -> None:
        """An entry-by-entry part (the [L21] elites' traces) in its own hash: all of it on a
        full rewrite, else what changed since the last write."""
        key = self.keys.part(part)
        if full:
            pipe.delete(key)
        elif removed:
            pipe.hdel(key, *removed)
        if added:
            pipe.hset(key, mapping={k: dumps(v) for k, v in added.items()})

    # --- the curriculum's calls ---------------------------------------------------------------

    def next_tasks(self, n: int, source: str = "") -> np.ndarray:
        """n task parameters for the episodes about to start: [n, d]."""
        return self.next_deal(n, source).tasks

    def next_deal(self, n: int, source: str = "") -> TaskDeal:
        """The tasks of the episodes about to start, [n, d], as a deal ([L21]: with the
        motions m_a to imitate, the batch and its region)."""
        deal = self.curriculum.next_deal(int(n))
        entry = dumps(
            {
                "time": time.time(),
                "source": source,
                "names": list(self.curriculum.space.names),
                "tasks": deal.tasks.tolist(),
                "region": deal.region,
                "batch": deal.batch,
            }
        )

        def record(pipe) -> None:
            pipe.lpush(self.keys.samples, entry)
            pipe.ltrim(self.keys.samples, 0, SAMPLES_LIMIT - 1)

        self._commit(("core",), record)
        return deal

    def ingest(self, episodes: list[EpisodeReport]) -> int:
        """Count finished episodes once each (by `episode_id`); returns how many were new."""
        unique = {e.episode_id: e for e in episodes}
        if not unique:
            return 0
        ids = list(unique)
        seen = self.redis.smismember(self.keys.seen, ids)
        new = [unique[i] for i, s in zip(ids, seen, strict=True) if not s]
        if not new:
            return 0
        new_ids = [e.episode_id for e in new]
        self.curriculum.ingest(new)
        self.recent_ids.extend(new_ids)
        parts = ("core", *self.curriculum.pending_parts())
        self._commit(parts, lambda pipe: pipe.sadd(self.keys.seen, *new_ids))
        return len(new)

    def update_marginal(self, layers: Layers, mu: float, iteration: int, refill: bool) -> None:
        """The learner's latest V̄ and μ; S is refilled by MCMC when `refill`."""
        self.curriculum.update_marginal(layers, mu, iteration, refill)
        parts = ("core", "marginal", "buffer") if refill else ("core", "marginal")
        self._commit(parts)

    def elite_data(self) -> tuple[np.ndarray, np.ndarray]:
        """([L21]) The elites' parameters and traces: P_θ's training set."""
        return self.curriculum.elite_data()

    def update_motion(self, layers, version: int, loss: float | None, stage: str) -> None:
        """([L21]) The learner's P_θ, its version and loss, and the bootstrap stage."""
        before = self.curriculum.stage
        self.curriculum.update_motion(layers, version, loss, stage)
        event = None
        if stage != before:
            event = ("stage_changed", f"bootstrap stage {before} -> {stage}")
        self._commit(("core", "motion"), event=event)

    def edge_tasks(self, n: int, seed: int) -> np.ndarray | None:
        """Tasks on the current range's edge for the learner's edge test (`WidenConfig`)."""
        return self.curriculum.edge_tasks(n, seed)

    def judge_edge(self, episodes: int, falls: int) -> float:
        """The learner's edge test: `falls` of `episodes`; the range grows if it passed."""
        before = self.curriculum.width
        width = self.curriculum.judge_edge(episodes, falls)
        event = None
        if width != before:
            event = (
                "range_widened",
                f"range widened to {100 * width:.0f}% ({falls} of {episodes} fell at its edge)",
            )
        self._commit(("core",), event=event)
        return width

    def set_k(self, k: float) -> None:
        old = self.curriculum.sampler.k
        self.curriculum.set_k(k)
        self._commit(("core",), event=("k_changed", f"k changed from {old:g} to {k:g}"))

    # --- state ----------------------------------------------------------------------------------

    def to_state(self) -> dict:
        return self.curriculum.to_state()

    def from_state(self, state: dict) -> None:
        """Replace the state (a run resumed from a checkpoint)."""
        self.curriculum.from_state(state)
        self.rewrite_all = True  # every part, traces included
        self._commit(self.parts, event=("sampler_loaded", "sampler loaded a checkpoint's state"))

    def summary(self) -> CurriculumSummary:
        return self.curriculum.summary()

    def digest(self) -> str:
        """sha256 of the whole state: equal digests, equal samplers."""
        blob = json.dumps(self.curriculum.to_state(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()

    def seen_count(self) -> int:
        return int(self.redis.scard(self.keys.seen))
