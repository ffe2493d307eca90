"""One learner writes a run: its lease is its fencing token. A learner whose lease was taken
over, or that could not renew it in time (a Redis outage longer than the lease), writes
nothing more: no Redis key (every write is a transaction conditioned on the lease) and no
metrics row or checkpoint in the run directory (the trainer asks `holds` first)."""

from __future__ import annotations

import json

import pytest
import redis
from conftest import wait_until

from paramimic.config import ExperimentConfig
from paramimic.training.trainer import SerialBackend, Trainer, WriteRefused
from services.keys import RunKeys
from services.launch.redis_server import EmbeddedRedis
from services.learner.reporter import RunReporter
from services.store import LeaseLost

CFG = {
    "character": "hopper",
    "task": {"leg_length": [0.9, 1.1], "target_velocity": [1.0, 1.0]},
    "env": {"max_episode_seconds": 1.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 1, "hidden_sizes": [16]},
    "actors": {"num_envs": 2},
    "train": {"checkpoint_every": 1},
}


def test_a_learner_whose_lease_was_taken_writes_nothing_more(redis_server, tmp_path):
    cfg = ExperimentConfig.model_validate(CFG)
    first = RunReporter(redis_server.url, "fenced")
    first.acquire(lease_seconds=30)
    first.start(cfg, tmp_path, 1000, None)
    first.progress({"iteration": 1, "env_steps": 256})
    keys = RunKeys("fenced")
    r = redis.Redis.from_url(redis_server.url, decode_responses=True)
    r.set(keys.lease, "elsewhere:1:beef", ex=30)  # the lease lapsed and another learner took it
    with pytest.raises(LeaseLost):
        first.progress({"iteration": 2, "env_steps": 512})
    assert json.loads(r.hget(keys.progress, "iteration")) == 1
    assert not first.holds()  # and it never takes the lease back from its new owner
    with pytest.raises(LeaseLost):
        first.event("checkpoint", "should not appear")
    assert r.get(keys.lease) == "elsewhere:1:beef"
    first.release()  # releasing leaves the new owner's lease alone
    assert r.get(keys.lease) == "elsewhere:1:beef"


def test_a_redis_outage_longer_than_the_lease_stops_the_writes(tmp_path):
    """The learner cannot renew: past 2/3 of its lease it stops writing its run directory (the
    trainer raises WriteRefused, no metrics row, no checkpoint, also none on the way out);
    once Redis is back and nobody took the lease, it may take it again."""
    server = EmbeddedRedis(tmp_path / "redis")
    server.start()
    try:
        reporter = RunReporter(server.url, "outage", retry_seconds=1.0)
        reporter.acquire(lease_seconds=3)
        cfg = ExperimentConfig.model_validate(CFG | {"name": "outage"})
        run = tmp_path / "run"
        trainer = Trainer(cfg, run)
        backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
        trainer.train(backend, 2 * 256, may_write=reporter.holds)
        rows = (run / "metrics.jsonl").read_text().splitlines()
        checkpoints = sorted(p.name for p in (run / "checkpoints").glob("ckpt_*.pt"))
        assert len(rows) == 2 and checkpoints == ["ckpt_000001.pt", "ckpt_000002.pt"]
        server.stop()
        wait_until(lambda: not reporter.holds(), 10, "the lease to lapse for this learner")
        with pytest.raises(WriteRefused, match="may no longer write"):
            trainer.train(backend, 6 * 256, may_write=reporter.holds)
        assert (run / "metrics.jsonl").read_text().splitlines() == rows
        assert sorted(p.name for p in (run / "checkpoints").glob("ckpt_*.pt")) == checkpoints
        server.start()  # back, the lease expired and free: this learner takes it again
        wait_until(reporter.holds, 20, "the learner to retake its free lease",
                   retry_on=(redis.RedisError,))  # fmt: skip
        backend.close()
    finally:
        server.stop()


def test_the_sampler_writes_only_under_the_learners_lease(redis_server):
    """The sampler actor's writes carry the learner's token too: once the lease is another
    learner's, its commits are refused and the curriculum in Redis stays as it was."""
    from paramimic.messages import EpisodeReport
    from services.sampler.service import SamplerService

    keys = RunKeys("fenced-sampler")
    r = redis.Redis.from_url(redis_server.url, decode_responses=True)
    r.set(keys.lease, "here:1:aaaa", ex=30)
    cfg = ExperimentConfig.model_validate(CFG).model_dump(mode="json")
    sampler = SamplerService(cfg, redis_server.url, "fenced-sampler", owner="here:1:aaaa")
    deal = sampler.next_deal(4)
    before = r.hget(keys.curriculum, "summary")
    r.set(keys.lease, "elsewhere:2:bbbb", ex=30)
    report = EpisodeReport("e1", deal.tasks[0], 1.0, 10, False, False, {}, False)
    with pytest.raises(LeaseLost):
        sampler.ingest([report])
    assert r.hget(keys.curriculum, "summary") == before


def test_a_lease_of_a_pid_now_another_process_is_dead():
    """In a container the learner is pid 1 with the same hostname after every restart: the
    owner also says when its process started, so a restarted learner sees its predecessor's
    lease as dead instead of waiting for it to expire."""
    import os
    import socket

    from services.learner.reporter import _dead_here, _process_start

    me, pid = socket.gethostname(), os.getpid()
    assert not _dead_here(f"{me}:{pid}:{_process_start(pid)}:abcd")  # this very process
    assert _dead_here(f"{me}:{pid}:0000.1:abcd")  # the same pid, another process
    assert not _dead_here(f"{me}:{pid}:abcd")  # an older release's owner: pid alive, not dead
    assert not _dead_here(f"elsewhere:{pid}:0000.1:abcd")  # another machine: not ours to judge
