"""Redis clients for the services: reconnect with backoff while a server restarts.

A command that fails on a lost connection, a timeout or a server still loading its AOF is
retried with exponential backoff for up to `retry_seconds`; after that the error propagates.
Writes that the services retry are absolute (HSET, SADD, ZADD after a range delete), so a
transaction applied twice leaves the same state.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable

import redis
from redis.backoff import ExponentialBackoff
from redis.exceptions import AuthenticationError, BusyLoadingError
from redis.exceptions import ConnectionError as RedisConnectionError
from redis.exceptions import TimeoutError as RedisTimeoutError
from redis.retry import Retry

from services.keys import EVENTS_LIMIT, RunKeys


class RedisAuthFailed(redis.exceptions.RedisError):
    """Wrong or missing password: not worth retrying (redis-py files it under ConnectionError)."""


RETRYABLE = (RedisConnectionError, RedisTimeoutError, BusyLoadingError, TimeoutError)
BACKOFF_CAP = 0.5  # seconds between attempts, at most


def connect(
    url: str,
    retry_seconds: float = 120.0,
    on_connect: Callable[[], None] | None = None,
) -> redis.Redis:
    """A client for `url` (redis://[:password@]host:port/db or unix://path) that retries.

    `on_connect` runs after every (re)connection, so that a caller can rewrite state a
    restarted server may have lost.
    """

    def connected(conn) -> None:
        try:
            conn.on_connect()
        except AuthenticationError as e:
            raise RedisAuthFailed(f"Redis refused the credentials: {e}") from e
        if on_connect is not None:
            on_connect()

    return redis.Redis.from_url(
        url,
        decode_responses=True,
        socket_timeout=10.0,
        socket_connect_timeout=2.0,
        retry=Retry(
            ExponentialBackoff(cap=BACKOFF_CAP, base=0.02),
            retries=int(retry_seconds / BACKOFF_CAP) + 8,
            supported_errors=RETRYABLE,
        ),
        retry_on_error=list(RETRYABLE),
        redis_connect_func=connected,
    )


def finite(value):
    """`value` with every NaN/±inf float (Python or numpy, at any depth) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, str):  # numpy arrays and scalars
        return finite(value.tolist())
    return value


def dumps(value) -> str:
    """JSON for Redis and the API: standard JSON only, non-finite numbers stored as null."""
    return json.dumps(finite(value), allow_nan=False)


def add_event(
    pipe: redis.client.Pipeline | redis.Redis,
    keys: RunKeys,
    kind: str,
    message: str,
    data: dict | None = None,
) -> None:
    """Append one event (restart, phase change, checkpoint, ...) to the run's stream."""
    pipe.xadd(
        keys.events,
        {
            "type": kind,
            "message": message,
            "data": dumps(data or {}),
            "time": f"{time.time():.3f}",
        },
        maxlen=EVENTS_LIMIT,
        approximate=True,
    )
