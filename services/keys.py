"""Every Redis key and Ray actor name paramimic uses, in one place. Keys are namespaced by run id.

paramimic:runs                        sorted set: run id -> start time (unix seconds)
paramimic:run:{run}:meta              hash: name, config (JSON), status, started_at, updated_at,
                                      run_dir, api_url
paramimic:run:{run}:progress          hash: iteration, env_steps, episodes, steps_per_second,
                                      mean_return, fall_percent, updated_at
paramimic:run:{run}:history           sorted set: one JSON metrics record per iteration,
                                      scored by iteration, bounded to HISTORY_LIMIT
paramimic:run:{run}:curriculum        hash: core (JSON: rng, k, μ, counters), buffer (JSON),
                                      marginal (JSON V̄ layers), summary (JSON, for the API),
                                      grid (JSON V̄ over the display dims), digest
                                      [L21]: elites (JSON: params, fitness, keys), motion
                                      (JSON P_θ layers, version, loss), density (JSON grid)
paramimic:run:{run}:traces            hash: elite key -> JSON trace [K][D] of (d, τ) ([L21])
paramimic:run:{run}:seen              set: ingested episode ids (idempotent ingestion)
paramimic:run:{run}:samples           list: the latest task batches (JSON), newest first
paramimic:run:{run}:events            stream: type, message, data (JSON), time
paramimic:run:{run}:control           hash: paused (0/1), k (requested uniformity)
paramimic:run:{run}:lease             string: the owning learner (host:pid:start:nonce), with a TTL
                                      its heartbeat renews; gone = the learner is gone
"""

from __future__ import annotations

import re

PREFIX = "paramimic"
RUNS = f"{PREFIX}:runs"
RAY_NAMESPACE = "paramimic"

HISTORY_LIMIT = 10_000  # iterations kept in the history
SAMPLES_LIMIT = 100  # task batches kept
EVENTS_LIMIT = 10_000  # events kept (approximately: MAXLEN ~)
LEASE_SECONDS = 15  # a learner that stops renewing its lease for this long is gone ("stale")

RUN_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")


class RunKeys:
    """The keys of one run."""

    def __init__(self, run_id: str) -> None:
        if not RUN_ID.match(run_id):
            raise ValueError(f"invalid run id {run_id!r}: letters, digits, '_', '.', '-'")
        self.run_id = run_id
        self.base = base = f"{PREFIX}:run:{run_id}"
        self.meta = f"{base}:meta"
        self.progress = f"{base}:progress"
        self.history = f"{base}:history"
        self.curriculum = f"{base}:curriculum"
        self.seen = f"{base}:seen"  # the ids of the episodes the sampler counted
        # the ids of the episodes whose samples reached the learner, and how many arrived (a
        # count above the set's size: an episode learned twice)
        self.learned = f"{base}:learned"
        self.traces = self.part("traces")
        self.samples = f"{base}:samples"
        self.events = f"{base}:events"
        self.control = f"{base}:control"
        self.lease = f"{base}:lease"

    def part(self, name: str) -> str:
        """The hash of a curriculum state part kept entry by entry (the [L21] `traces`)."""
        return f"{self.base}:{name}"


class SamplerUnavailable(RuntimeError):
    """What a rollout actor raises when the sampler actor does not answer it within
    actors.sampler_timeout: the learner files the dropped fragment under the sampler."""


def sampler_actor_name(run_id: str) -> str:
    """The named Ray actor that owns a run's curriculum (in RAY_NAMESPACE)."""
    return f"sampler:{run_id}"
