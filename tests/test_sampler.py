"""The sampler service: its state in a real Redis, idempotent ingestion, and surviving a kill -9
of itself (a real Ray actor) and of the Redis server (AOF) during real training runs."""

from __future__ import annotations

import json
import os
import signal
import threading

import httpx
import numpy as np
import pytest
import ray
import redis
from conftest import wait_until

from paramimic.config import ExperimentConfig
from paramimic.messages import EpisodeReport
from services.keys import RunKeys
from services.launch.processes import port_is_free
from services.launch.redis_server import EmbeddedRedis
from services.launch.stack import ray_stack
from services.learner.reporter import RunReporter
from services.sampler.service import SamplerService

CFG = {
    "character": "hopper",
    "task": {"leg_length": [0.8, 1.2], "torso_length": [0.9, 1.1], "target_velocity": [1, 1]},
    "env": {"max_episode_seconds": 1.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
    "curriculum": {"k": 10.0, "p_mcmc": 1, "n_mcmc": 100},
    "actors": {"num_actors": 2, "num_envs": 4},
    "train": {"checkpoint_every": 100, "seed": 3},
}


def _cfg(**actors) -> ExperimentConfig:
    return ExperimentConfig.model_validate({**CFG, "actors": {**CFG["actors"], **actors}})


def _episode(i: int, ret: float = 10.0) -> EpisodeReport:
    return EpisodeReport(f"ep-{i}", np.ones(3), ret, 50, i % 2 == 0, False, {}, i % 2 == 0)


def _layers(seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    return [
        (rng.normal(size=(3, 8)), rng.normal(size=8)),
        (rng.normal(size=(8, 1)), np.array([5.0])),
    ]


def test_ingesting_the_same_summaries_twice_changes_nothing(redis_server, run_id):
    sampler = SamplerService(_cfg().model_dump(mode="json"), redis_server.url, run_id)
    batch = [_episode(i) for i in range(5)]
    assert sampler.ingest(batch) == 5
    digest, seen = sampler.digest(), sampler.seen_count()
    assert sampler.ingest(batch) == 0  # a retried call
    assert sampler.ingest(batch[2:] + batch[:1]) == 0  # any subset, any order
    assert sampler.digest() == digest and sampler.seen_count() == seen == 5
    # a batch with one new episode and a duplicate of it counts it once
    assert sampler.ingest([_episode(9, 1.0), _episode(9, 1.0), batch[0]]) == 1
    summary = sampler.summary()
    assert summary.episodes == 6
    assert summary.mean_return == pytest.approx((5 * 10.0 + 1.0) / 6)
    assert summary.fall_percent == pytest.approx(100 * 3 / 6)  # ep-0, 2, 4 fell


def test_a_new_sampler_on_the_same_run_continues_exactly_where_it_was(redis_server, run_id):
    config = _cfg().model_dump(mode="json")
    a = SamplerService(config, redis_server.url, run_id)
    a.next_tasks(7, "actor0")
    a.update_marginal(_layers(), mu=5.0, iteration=3, refill=True)
    a.ingest([_episode(i) for i in range(4)])
    a.next_tasks(3, "actor1")
    a.set_k(2.5)
    b = SamplerService(config, redis_server.url, run_id, restarted=True)
    assert b.digest() == a.digest()
    assert b.curriculum.sampler.adaptive and b.curriculum.sampler.k == 2.5
    np.testing.assert_array_equal(a.next_tasks(5), b.next_tasks(5))  # the same rng state too
    # every change was one transaction: the stored parts, the summary and the grid agree
    stored = redis.Redis.from_url(redis_server.url, decode_responses=True).hgetall(
        RunKeys(run_id).curriculum
    )
    assert json.loads(stored["summary"])["k"] == 2.5
    grid = json.loads(stored["grid"])
    assert grid["dims"] == ["leg_length", "torso_length"] and len(grid["values"]) == 21


def test_the_learners_edge_test_widens_the_range_in_one_transaction(redis_server, run_id):
    raw = _cfg().model_dump(mode="json")
    raw["curriculum"]["widen"] = {"start": 0.2, "step": 0.1, "promote_on": "edge"}
    a = SamplerService(raw, redis_server.url, run_id)
    tasks = a.edge_tasks(8, 5)
    assert tasks.shape == (8, 3) and np.all(np.abs(tasks[:, 0] - 1.0) <= 0.2 * 0.2 + 1e-12)
    assert a.judge_edge(16, 12) == pytest.approx(0.2)  # 75 % fell: stays
    assert a.judge_edge(16, 2) == pytest.approx(0.3)
    b = SamplerService(raw, redis_server.url, run_id, restarted=True)
    assert b.curriculum.width == pytest.approx(0.3) and b.summary().range_width == 0.3
    events = redis.Redis.from_url(redis_server.url, decode_responses=True).xrange(
        RunKeys(run_id).events
    )
    widened = [f["message"] for _, f in events if f["type"] == "range_widened"]
    assert widened == ["range widened to 30% (2 of 16 fell at its edge)"]


class Gate:
    """Holds the learner before its next iteration while closed; `held` says it is waiting."""

    def __init__(self) -> None:
        self.open_ = threading.Event()
        self.open_.set()
        self.held = threading.Event()

    def __call__(self) -> None:
        if not self.open_.is_set():
            self.held.set()
        self.open_.wait()


def _train_in_thread(stack, total_steps, gate=None):
    """Run stack.trainer.train in a thread, held by `gate` before each iteration."""
    errors: list[Exception] = []
    metrics: list[dict] = []

    def run():
        try:
            stack.trainer.train(
                stack.backend, total_steps, on_metrics=metrics.append, before_iteration=gate
            )
        except Exception as e:  # surfaced by the caller's assertions
            errors.append(e)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, metrics, errors


def _events(url: str, run_id: str) -> list[str]:
    r = redis.Redis.from_url(url, decode_responses=True)
    return [f["type"] for _, f in r.xrange(RunKeys(run_id).events)]


def test_kill_9_of_the_sampler_actor_loses_nothing(
    local_ray, redis_server, api_url, run_id, tmp_path
):
    cfg = _cfg(steps_per_fragment=100)
    RunReporter(redis_server.url, run_id).start(cfg, tmp_path, 0, None)  # the API lists the run
    gate = Gate()
    with ray_stack(cfg, tmp_path, redis_server.url, run_id) as stack:
        total = 8 * 2 * 4 * 100
        thread, metrics, errors = _train_in_thread(stack, total, gate)
        wait_until(lambda: len(metrics) >= 2, 120, "two iterations")
        # 1) at rest (the learner held before an iteration): the restarted sampler's state
        #    equals the state before the kill
        gate.open_.clear()
        wait_until(gate.held.is_set, 120, "the learner to hold")  # sync mode: no call in flight
        n = len(metrics)
        before = ray.get(stack.sampler.digest.remote())
        pid = ray.get(stack.sampler.pid.remote())
        os.kill(pid, signal.SIGKILL)
        assert ray.get(stack.sampler.pid.remote(), timeout=120) != pid  # restarted by Ray
        assert ray.get(stack.sampler.digest.remote()) == before
        events = httpx.get(f"{api_url}/runs/{run_id}/events").json()
        restart = next(e for e in events if e["type"] == "sampler_restarted")
        assert restart["data"]["digest"] == before  # what it reloaded is what it had
        # 2) mid-fragment: actors are calling it; Ray retries their calls on the new sampler
        gate.open_.set()
        wait_until(lambda: len(metrics) >= n + 2, 120, "training to go on")
        served = ray.get(stack.sampler.summary.remote()).tasks_served
        wait_until(
            lambda: ray.get(stack.sampler.summary.remote()).tasks_served > served, 120,
            "an actor to ask the sampler for tasks", 0.02,
        )  # fmt: skip
        os.kill(ray.get(stack.sampler.pid.remote()), signal.SIGKILL)
        thread.join(timeout=600)
        assert not thread.is_alive() and not errors, errors
        assert stack.trainer.progress.env_steps >= total
        # every finished episode reached the sampler exactly once, retries or not
        summary = stack.trainer.curriculum.summary()
        assert summary.episodes == stack.trainer.progress.episodes
        assert ray.get(stack.sampler.seen_count.remote()) == summary.episodes
    assert _events(redis_server.url, run_id).count("sampler_restarted") == 2


def _in_aof(server: EmbeddedRedis, ids) -> bool:
    """Whether the server's append-only files on disk hold every id."""
    data = b"".join(p.read_bytes() for p in server.data_dir.rglob("*.aof"))
    return all(i.encode() in data for i in ids)


def test_a_redis_restart_during_a_run_loses_nothing_acknowledged(local_ray, run_id, tmp_path):
    server = EmbeddedRedis(tmp_path / "redis")
    server.start()
    try:
        cfg = _cfg(steps_per_fragment=100)
        with ray_stack(cfg, tmp_path, server.url, run_id) as stack:
            thread, metrics, errors = _train_in_thread(stack, 10 * 2 * 4 * 100)
            wait_until(lambda: len(metrics) >= 2, 120, "two iterations")
            client = redis.Redis.from_url(server.url, decode_responses=True)
            acknowledged = client.smembers(RunKeys(run_id).seen)
            episodes_before = json.loads(client.hget(RunKeys(run_id).curriculum, "summary"))[
                "episodes"
            ]
            client.close()
            # the next `appendfsync everysec` has written every acknowledged id to the AOF
            wait_until(lambda: _in_aof(server, acknowledged), 30, "the AOF to hold the ids")
            server.kill()  # SIGKILL: no shutdown fsync
            wait_until(lambda: port_is_free("127.0.0.1", server.port), 30, "the port")
            server.start()  # same port, same AOF
            thread.join(timeout=600)
            assert not thread.is_alive() and not errors, errors
            assert len(metrics) == 10  # training went on through the outage
            client = redis.Redis.from_url(server.url, decode_responses=True)
            keys = RunKeys(run_id)
            assert all(client.smismember(keys.seen, list(acknowledged)))
            summary = json.loads(client.hget(keys.curriculum, "summary"))
            assert summary["episodes"] >= episodes_before
            # the sampler rewrote its state after reconnecting: Redis agrees with it
            assert summary == stack.trainer.curriculum.summary().to_dict()
            assert client.scard(keys.seen) == summary["episodes"] == stack.trainer.progress.episodes
            client.close()
    finally:
        server.stop()
