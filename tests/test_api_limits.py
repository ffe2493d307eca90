"""The API can't be starved or confused by one client or by damaged state — a real
uvicorn (`paramimic api`) over its own real Redis server."""

from __future__ import annotations

import json
import socket

import httpx
import numpy as np
import pytest
import redis

from paramimic.config import ExperimentConfig
from services.keys import RunKeys
from services.launch.api_process import ApiProcess
from services.launch.processes import free_port
from services.launch.redis_server import EmbeddedRedis
from services.learner.reporter import RunReporter

TOKEN = "limits-test-token"
CFG = {"name": "limits", "character": "hopper", "task": {"leg_length": [0.8, 1.2]}}


@pytest.fixture
def stack(tmp_path):
    server = EmbeddedRedis(tmp_path / "redis")
    server.start()
    api = ApiProcess(server.url, "127.0.0.1", free_port(), TOKEN, tmp_path / "api.log")
    api.start()
    yield server, api.url
    api.stop()
    server.stop()


def _start_run(url: str, run_id: str, tmp_path) -> RunReporter:
    reporter = RunReporter(url, run_id)
    reporter.start(ExperimentConfig.model_validate(CFG), tmp_path, 1000, None)
    return reporter


def test_oversized_bodies_get_413_before_parsing(stack, tmp_path):
    server, url = stack
    _start_run(server.url, "big-body", tmp_path)
    auth = {"Authorization": f"Bearer {TOKEN}"}
    put = f"{url}/runs/big-body/curriculum/k"
    assert httpx.put(put, json={"k": 3}, headers=auth).status_code == 202
    padded = json.dumps({"k": 3, "pad": "x" * 100_000})
    r = httpx.put(put, content=padded, headers=auth | {"Content-Type": "application/json"})
    assert r.status_code == 413 and "4096 bytes" in r.json()["detail"]

    def chunks():  # no Content-Length: counted as it streams
        for _ in range(100):
            yield b"x" * 1000

    r = httpx.put(put, content=chunks(), headers=auth | {"Content-Type": "application/json"})
    assert r.status_code == 413


def test_runs_are_paginated(stack, tmp_path):
    server, url = stack
    for i in range(5):
        _start_run(server.url, f"page-run-{i}", tmp_path)
    r = httpx.get(f"{url}/runs", params={"limit": 2})
    assert r.headers["X-Total-Count"] == "5"
    first = [x["run_id"] for x in r.json()]
    second = [x["run_id"] for x in httpx.get(f"{url}/runs?offset=2&limit=2").json()]
    last = [x["run_id"] for x in httpx.get(f"{url}/runs?offset=4&limit=2").json()]
    assert len(first) == 2 and len(second) == 2 and len(last) == 1
    assert sorted(first + second + last) == [f"page-run-{i}" for i in range(5)]
    assert httpx.get(f"{url}/runs?limit=100000").status_code == 422


def test_nan_metrics_are_stored_and_served_as_null(stack, tmp_path):
    server, url = stack
    reporter = _start_run(server.url, "nan-run", tmp_path)
    metrics = {"iteration": 1, "env_steps": 10, "mean_return": float("nan")}
    reporter.progress(metrics | {"fall_percent": float("inf"), "kl": float("-inf")})
    raw = redis.Redis.from_url(server.url).zrange(RunKeys("nan-run").history, 0, -1)[0].decode()
    assert "NaN" not in raw and "Infinity" not in raw
    assert json.loads(raw)["mean_return"] is None
    r = httpx.get(f"{url}/runs/nan-run/history")
    assert r.status_code == 200 and "NaN" not in r.text
    assert r.json()["items"][0]["fall_percent"] is None
    assert httpx.get(f"{url}/runs/nan-run/progress").json()["mean_return"] is None


def test_damaged_stored_json_gets_a_clear_answer_not_a_5xx(stack, tmp_path):
    server, url = stack
    reporter = _start_run(server.url, "damaged-run", tmp_path)
    reporter.progress({"iteration": 1, "env_steps": 10, "mean_return": 1.0})
    client = redis.Redis.from_url(server.url)
    keys = RunKeys("damaged-run")
    client.zadd(keys.history, {"{not json": 2})
    client.hset(keys.progress, "env_steps", "[[[")
    client.hset(keys.curriculum, "summary", '{"task_ranges": {"a": ')
    for path in ("history", "progress", "curriculum", "curriculum/elites"):
        r = httpx.get(f"{url}/runs/damaged-run/{path}")
        assert r.status_code < 500, (path, r.status_code, r.text)
        assert "damaged" in r.json()["detail"], (path, r.text)


def test_redis_down_is_503_with_retry_after_and_no_address(stack):
    server, url = stack
    server.kill()
    r = httpx.get(f"{url}/runs", timeout=30)
    assert r.status_code == 503 and r.headers["Retry-After"].isdigit()
    body = r.text
    assert str(server.port) not in body and "127.0.0.1" not in body
    assert socket.gethostname() not in body


def test_redis_retries_end_at_their_wall_clock_limit(tmp_path):
    """A Redis that stops answering (SIGSTOP: the socket stays open, each
    attempt would wait for its timeout) fails a command after about `retry_seconds`."""
    import os
    import signal
    import time

    from services.store import connect

    server = EmbeddedRedis(tmp_path / "stopped")
    server.start()
    client = connect(server.url, retry_seconds=2.0)
    assert client.ping()
    os.kill(server.process.pid, signal.SIGSTOP)
    try:
        start = time.monotonic()
        with pytest.raises(redis.exceptions.RedisError):
            client.get("x")
        elapsed = time.monotonic() - start
        assert elapsed < 20.0, elapsed  # counted retries alone: 12 x a 10 s socket timeout
    finally:
        os.kill(server.process.pid, signal.SIGCONT)
        server.stop()


def test_a_polled_elite_set_is_parsed_once_and_thinned_for_plots(tmp_path):
    """`/curriculum/elites` parses the stored set and builds its k-d tree once per version,
    not per request (a dashboard polls it every 2 s), and `spread` gives a plot an evenly
    spaced subset instead of the first `limit`."""
    from fastapi.testclient import TestClient

    from services.api.app import create_app
    from services.api.settings import Settings

    server = EmbeddedRedis(tmp_path / "redis")
    server.start()
    try:
        _start_run(server.url, "elite-run", tmp_path)
        client = redis.Redis.from_url(server.url)
        keys = RunKeys("elite-run")
        ranges = {"gravity": [0.5, 1.5], "jump_height": [0.0, 0.6]}
        n = 20_001
        g = np.linspace(0.5, 1.5, n)
        state = {
            "params": np.stack([g, np.full(n, 0.3)], 1).tolist(),
            "fitness": np.linspace(0.2, 1.0, n).tolist(),
            "keys": [f"e{i}" for i in range(n)],
        }
        client.hset(
            keys.curriculum,
            mapping={"summary": json.dumps({"task_ranges": ranges}), "elites": json.dumps(state)},
        )
        app = create_app(Settings(redis_url=server.url))
        with TestClient(app, base_url="http://127.0.0.1") as c:
            for _ in range(5):
                r = c.get("/runs/elite-run/curriculum/elites", params={"limit": 100_000})
                assert r.status_code == 200 and len(r.json()["items"]) == n
            assert app.state.elite_cache.builds == 1
            near = c.get("/runs/elite-run/curriculum/elites", params={"near": "1.0,0.3", "k": 1})
            assert near.json()["items"][0]["key"] == f"e{(n - 1) // 2}"
            assert app.state.elite_cache.builds == 1
            thin = c.get("/runs/elite-run/curriculum/elites", params={"limit": 5, "spread": True})
            got = [e["params"]["gravity"] for e in thin.json()["items"]]
            assert got == pytest.approx([0.5, 0.75, 1.0, 1.25, 1.5], abs=1e-4)
            first = c.get("/runs/elite-run/curriculum/elites", params={"limit": 5}).json()
            assert [e["key"] for e in first["items"]] == [f"e{i}" for i in range(5)]
            # the sampler writes a new version: parsed again, the new set served
            state = {k: v[:10] for k, v in state.items()}
            client.hset(keys.curriculum, "elites", json.dumps(state))
            r = c.get("/runs/elite-run/curriculum/elites").json()
            assert r["total"] == 10 and app.state.elite_cache.builds == 2
    finally:
        server.stop()
