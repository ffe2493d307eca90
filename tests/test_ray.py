"""The distributed actor-learner on a real local Ray (started and stopped here, on loopback)."""

import os
import signal
import threading

import numpy as np
import pytest
import ray
from conftest import wait_until

from paramimic.config import ExperimentConfig
from paramimic.training import checkpoint
from paramimic.training.trainer import SerialBackend, Trainer


def _cfg(**actors) -> ExperimentConfig:
    return ExperimentConfig.model_validate(
        {
            "character": "hopper",
            "task": {"leg_length": [0.8, 1.2], "target_velocity": [1.0, 1.0]},
            "env": {"max_episode_seconds": 2.0},
            "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
            "curriculum": {"k": 10.0, "p_mcmc": 1, "n_mcmc": 100},
            "actors": {"num_actors": 2, "num_envs": 4, **actors},
            "train": {"checkpoint_every": 1, "seed": 5},
        }
    )


def test_two_actors_deliver_fragments_and_training_advances(distributed, tmp_path):
    cfg = _cfg()
    trainer, backend = distributed(cfg, tmp_path)
    assert backend.num_actors == 2 and backend.steps == 32  # 256 / (2 actors x 4 envs)
    frags = backend.collect(trainer.learner.weights(), trainer.learner.version)
    assert len(frags) == 2
    for f in frags:
        assert f.obs.shape == (32, 4, trainer.obs_dim)
        assert f.actions.shape == (32, 4, trainer.act_dim)
        assert f.rewards.shape == f.dphi.shape == f.terminated.shape == (32, 4)
        assert f.policy_version == 0
    assert {e.episode_id.split("-")[1] for f in frags for e in f.episodes} <= {"w0", "w1"}
    trainer.train(backend, total_steps=3 * 256)
    assert trainer.progress.iteration == 3
    assert trainer.progress.env_steps == 3 * 256
    assert backend.stats()["actor_restarts"] == 0
    # the actors reported every finished episode to the sampler
    episodes = trainer.progress.episodes + sum(len(f.episodes) for f in frags)
    assert trainer.curriculum.summary().episodes == episodes


def test_the_learners_edge_test_widens_the_sampler_actors_range(distributed, tmp_path):
    raw = _cfg().model_dump()
    raw["env"]["max_episode_seconds"] = 0.3  # too short to fall: every edge test passes
    raw["curriculum"]["widen"] = {"start": 0.3, "step": 0.2, "window": 4, "check_every": 1,
                                  "promote_on": "edge", "promote_below": 0.2}  # fmt: skip
    trainer, backend = distributed(ExperimentConfig.model_validate(raw), tmp_path)
    rows = [trainer.iteration(backend) for _ in range(2)]
    assert [(r["edge_fall_percent"], r["edge_env_steps"]) for r in rows] == [(0.0, 36)] * 2
    assert [r["range_width"] for r in rows] == pytest.approx([0.5, 0.7])
    # the width is the sampler actor's: the rollout actors' tasks come from its range
    legs = trainer.curriculum.next_tasks(200)[:, 0]
    assert np.all(np.abs(legs - 1.0) <= 0.7 * 0.2 + 1e-9) and np.ptp(legs) > 0.1


def test_killed_actor_is_restarted_and_the_run_finishes(distributed, tmp_path):
    cfg = _cfg(steps_per_fragment=150)  # fragments long enough to be killed in the middle
    trainer, backend = distributed(cfg, tmp_path)
    victim = backend.pids()[0]
    first_done = threading.Event()
    metrics = []

    def on_metrics(m):
        metrics.append(m)
        first_done.set()

    errors = []

    def run():
        try:
            trainer.train(backend, total_steps=4 * 2 * 4 * 150, on_metrics=on_metrics)
        except Exception as e:  # surfaced by the assertion below
            errors.append(e)

    thread = threading.Thread(target=run)
    thread.start()
    try:
        assert first_done.wait(timeout=300)
        threading.Event().wait(0.5)  # the actors are now in the middle of the next fragment
        os.kill(victim, signal.SIGKILL)
        thread.join(timeout=600)
        assert not thread.is_alive() and not errors, errors
        assert trainer.progress.env_steps >= 4 * 2 * 4 * 150  # every iteration ran
        assert backend.stats()["actor_restarts"] == 1
        assert metrics[-1]["actor_restarts"] == 1
        assert victim not in _pids_when_back(backend)  # a new process took the actor's place
    finally:
        thread.join(timeout=600)


def _pids_when_back(backend, timeout=120.0):
    """Actor pids, once a restarting actor answers again (the run may end before it is back)."""
    retry = (ray.exceptions.RayActorError,)
    return wait_until(backend.pids, timeout, "the actor to answer again", 0.5, retry)


def test_resume_restores_identical_state(distributed, tmp_path):
    cfg = _cfg()
    first, backend = distributed(cfg, tmp_path)
    first.train(backend, total_steps=2 * 256)
    backend.close()  # its CPUs go to the resumed run's actors (else they wait lost_timeout)
    second, _ = distributed(cfg, tmp_path, suffix="-resumed")
    second.load_state_dict(checkpoint.load(tmp_path))
    a, b = first.learner.state_dict(), second.learner.state_dict()
    for k in a["policy"]:
        assert a["policy"][k].numpy().tobytes() == b["policy"][k].numpy().tobytes()
    for group in ("policy_opt", "value_opt"):
        for sid, st in a[group]["state"].items():
            for name, t in st.items():
                assert t.numpy().tobytes() == b[group]["state"][sid][name].numpy().tobytes()
    np.testing.assert_array_equal(a["normalizer"]["mean"], b["normalizer"]["mean"])
    assert second.progress.iteration == 2
    assert second.curriculum.to_state() == first.curriculum.to_state()


def test_serial_and_ray_give_the_same_fragments(distributed, tmp_path):
    cfg = _cfg(num_actors=1)
    a = Trainer(cfg, tmp_path / "serial")
    b, remote = distributed(cfg, tmp_path / "ray")
    b.learner.policy.load_state_dict(a.learner.policy.state_dict())
    serial = SerialBackend(cfg, a.obs_dim, a.act_dim, a.curriculum)
    for _ in range(2):
        [fs] = serial.collect(a.learner.weights(), 0)
        [fr] = remote.collect(b.learner.weights(), 0)
        for name in (
            "obs",
            "actions",
            "logp",
            "values",
            "next_values",
            "rewards",
            "terminated",
            "truncated",
            "task_index",
            "tasks",
        ):
            np.testing.assert_array_equal(getattr(fs, name), getattr(fr, name), name)
        # the same episodes; only the ids differ (a Ray actor's carry a per-process token)
        strip = [{**e.to_dict(), "episode_id": None} for e in fs.episodes]
        assert strip == [{**e.to_dict(), "episode_id": None} for e in fr.episodes]
    assert a.curriculum.to_state() == b.curriculum.to_state()  # the same sampler state


def test_pipelined_mode_samples_during_the_update(distributed, tmp_path):
    cfg = _cfg(mode="pipelined")
    trainer, backend = distributed(cfg, tmp_path)
    metrics = []
    trainer.train(backend, total_steps=4 * 256, on_metrics=metrics.append)
    assert [m["policy_lag"] for m in metrics] == [0.0, 1.0, 1.0, 1.0]  # one version behind


def test_auto_sizes_the_pool_from_the_cluster_cpus(local_ray):
    from services.learner.actor_pool import resolve_num_actors

    assert resolve_num_actors("auto") == 3  # one per CPU of the cluster
    assert resolve_num_actors(5) == 5


def test_all_actors_gone_raises_after_the_timeout(distributed, tmp_path):
    from services.learner.ray_backend import AllActorsLost

    cfg = _cfg(lost_timeout=2.0)
    trainer, backend = distributed(cfg, tmp_path)
    # actors that start slower than lost_timeout join later: wait for both before killing them
    assert backend.wait_for_actors(2, timeout=60.0) == 2
    for actor in backend.actors:
        ray.kill(actor, no_restart=True)
    with pytest.raises(AllActorsLost, match="no rollout actor delivered"):
        trainer.train(backend, total_steps=20 * cfg.ppo.num_steps)
    assert checkpoint.load(tmp_path)["progress"]["iteration"] == 0  # checkpointed on the way out
