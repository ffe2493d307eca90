"""Redis clients for the services: reconnect with backoff while a server restarts.

A command that fails on a lost connection, a timeout or a server still loading its AOF is
retried with exponential backoff for up to `retry_seconds` of wall-clock time from its first
attempt (an attempt in flight at the deadline may add up to one socket timeout, 10 s); after that
the error propagates.
Writes that the services retry are absolute (HSET, SADD, ZADD after a range delete), so a
transaction applied twice leaves the same state.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from urllib.parse import quote, urlsplit, urlunsplit

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
SOCKET_TIMEOUT = 10.0  # seconds one command may take before it counts as failed


class DeadlineRetry(Retry):
    """redis-py's Retry with a wall-clock limit: a command is retried with backoff until
    `seconds` have passed since its first attempt (the count of retries alone does not bound the
    time when each attempt can wait for a socket timeout); then the last error propagates."""

    def __init__(self, seconds: float) -> None:
        super().__init__(
            ExponentialBackoff(cap=BACKOFF_CAP, base=0.02), retries=-1, supported_errors=RETRYABLE
        )
        self.seconds = seconds

    def call_with_retry(self, do, fail, is_retryable=None, with_failure_count=False):
        deadline = time.monotonic() + self.seconds
        self._backoff.reset()
        failures = 0
        while True:
            try:
                return do()
            except self._supported_errors as error:
                if is_retryable and not is_retryable(error):
                    raise
                failures += 1
                fail(error, failures) if with_failure_count else fail(error)
                pause = self._backoff.compute(failures)
                if time.monotonic() + pause >= deadline:
                    raise error
                time.sleep(pause)


class LeaseLost(RuntimeError):
    """The run's learner no longer holds its lease (it could not renew it in time, or another
    learner took it): its writes to the run's keys and files stop."""


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
        socket_timeout=min(SOCKET_TIMEOUT, retry_seconds),
        socket_connect_timeout=2.0,
        retry=DeadlineRetry(retry_seconds),
        retry_on_error=list(RETRYABLE),
        redis_connect_func=connected,
    )


def with_password(url: str, environ: dict | None = None) -> str:
    """`url` with the password from $REDIS_PASSWORD_FILE (a file, e.g. a compose secret) or
    $REDIS_PASSWORD when it has none, so that the password never has to be on a command line."""
    environ = os.environ if environ is None else environ
    parts = urlsplit(url)
    if parts.password or parts.scheme not in ("redis", "rediss"):
        return url
    password = None
    if environ.get("REDIS_PASSWORD_FILE"):
        password = Path(environ["REDIS_PASSWORD_FILE"]).read_text().strip()
    elif environ.get("REDIS_PASSWORD"):
        password = environ["REDIS_PASSWORD"]
    if not password:
        return url
    user = quote(parts.username or "", safe="")
    netloc = f"{user}:{quote(password, safe='')}@{parts.hostname}"
    if parts.port:
        netloc += f":{parts.port}"
    return urlunsplit(parts._replace(netloc=netloc))


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
