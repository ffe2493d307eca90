"""On a real local Ray: every fragment error has a defined outcome, nothing
waits forever, and a stop request is honoured while the learner waits for actors."""

from __future__ import annotations

import contextlib
import os
import signal
import time

import pytest
import ray
from conftest import wait_until

from paramimic.config import ExperimentConfig
from paramimic.training import checkpoint
from paramimic.training.trainer import StopRequested
from services.actors.rollout_actor import RolloutActor
from services.learner.ray_backend import FragmentsFailing, SamplerClient, SamplerFailed


def _cfg(**actors) -> ExperimentConfig:
    return ExperimentConfig.model_validate(
        {
            "character": "hopper",
            "task": {"leg_length": [0.8, 1.2], "target_velocity": [1.0, 1.0]},
            "env": {"max_episode_seconds": 2.0},
            "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 1},
            "actors": {"num_actors": 2, "num_envs": 4, **actors},
            "train": {"checkpoint_every": 100, "seed": 3},
        }
    )


@ray.remote(num_cpus=1, max_restarts=-1)
class FlakyActor(RolloutActor.__ray_actor_class__):
    """A rollout actor whose env raises on every `every`-th call (every = 1: always), or on
    every call after its first `after` ones."""

    def __init__(self, *args, every: int = 3, after: int | None = None, **kw) -> None:
        super().__init__(*args, **kw)
        self.calls, self.every, self.after = 0, every, after

    def sample(self, *args, **kw):
        self.calls += 1
        broken = self.calls > self.after if self.after is not None else False
        if broken or (self.after is None and self.calls % self.every == 0):
            raise FloatingPointError("mujoco: simulation unstable (injected)")
        return super().sample(*args, **kw)


@ray.remote(num_cpus=1, max_restarts=-1)
class RayFailingActor(RolloutActor.__ray_actor_class__):
    """Every 3rd fragment fails in Ray, not in the env: one that does not deserialize, or an
    error that does not."""

    def __init__(self, *args, every: int = 3, **kw) -> None:
        super().__init__(*args, **kw)
        self.calls, self.every = 0, every

    def sample(self, *args, **kw):
        # defined here, not in the module: the workers cannot import this test module, and
        # cloudpickle sends local classes by value
        class TwoArgError(Exception):
            """Pickles, but unpickling calls __init__ with one argument: Ray's
            UnserializableException on the learner."""

            def __init__(self, a, b):
                super().__init__(f"{a} {b}")

        def unloadable():
            raise ValueError("this object cannot be rebuilt on the learner (injected)")

        class Unloadable:
            """Pickles, but does not unpickle: Ray's RaySystemError on the learner."""

            def __reduce__(self):
                return (unloadable, ())

        self.calls += 1
        if self.calls % self.every == 0:
            if self.calls % (2 * self.every) == 0:
                raise TwoArgError(1, 2)
            return Unloadable()
        return super().sample(*args, **kw)


def _flaky(every: int, actor=FlakyActor, **more):
    class Options:  # spawner calls actor_class.options(...).remote(...)
        @staticmethod
        def options(**opts):
            inner = actor.options(**opts)

            class Remote:
                @staticmethod
                def remote(*args):
                    return inner.remote(*args, every=every, **more)

            return Remote

    return Options


def test_env_errors_drop_fragments_and_training_goes_on(distributed, tmp_path):
    trainer, backend = distributed(_cfg(), tmp_path, actor_class=_flaky(3))
    trainer.train(backend, total_steps=6 * 256)
    stats = backend.stats()
    assert trainer.progress.iteration >= 6
    assert stats["fragment_errors"] >= 2 and backend.fragment_errors.keys() == {"env_error"}
    assert stats["actor_restarts"] == 0  # an env error is not an actor death
    kinds = [(k, d["reason"]) for k, _, d in backend.take_events() if k == "fragment_error"]
    assert ("fragment_error", "env_error") in kinds


def test_fragments_ray_fails_are_dropped_and_training_goes_on(distributed, tmp_path):
    """RaySystemError (a fragment that does not deserialize) and UnserializableException (an
    error that does not) drop a fragment as an env error does; they used to end the run."""
    trainer, backend = distributed(_cfg(), tmp_path, actor_class=_flaky(3, RayFailingActor))
    trainer.train(backend, total_steps=8 * 256)
    assert trainer.progress.iteration >= 8
    assert backend.fragment_errors.keys() == {"ray_error"}
    assert backend.fragment_errors["ray_error"] >= 2
    said = " ".join(m for k, m, _ in backend.take_events() if k == "fragment_error")
    assert "RaySystemError" in said or "UnserializableException" in said


def _final_checkpoint_is_the_runs(trainer, run_dir) -> dict:
    """The run's latest.pt is the state it stopped in: its manifest matches, it loads, and it
    is at the iteration training reached."""
    latest = checkpoint.checkpoint_dir(run_dir) / checkpoint.LATEST
    assert checkpoint.verify(latest)  # a manifest, and the file matches it
    state = checkpoint.load(run_dir)
    assert state["progress"]["iteration"] == trainer.progress.iteration
    assert state["progress"]["env_steps"] == trainer.progress.env_steps
    return state


def test_a_persistent_env_error_stops_with_the_reason(distributed, tmp_path):
    cfg = _cfg(max_fragment_errors=4)
    trainer, backend = distributed(cfg, tmp_path, actor_class=_flaky(1))
    with pytest.raises(FragmentsFailing, match="simulation unstable"):
        trainer.train(backend, total_steps=4 * 256)
    assert trainer.progress.iteration == 0


def test_an_env_that_breaks_mid_run_stops_with_its_final_checkpoint(distributed, tmp_path):
    """Good iterations first, then every fragment fails: FragmentsFailing, and the final
    checkpoint (checkpoint_every is 100: only the way out writes one) holds those iterations."""
    cfg = _cfg(max_fragment_errors=4)
    trainer, backend = distributed(cfg, tmp_path, actor_class=_flaky(1, after=3))
    with pytest.raises(FragmentsFailing, match="simulation unstable"):
        trainer.train(backend, total_steps=50 * 256)
    assert trainer.progress.iteration >= 2
    _final_checkpoint_is_the_runs(trainer, tmp_path)


def test_a_hung_actor_is_killed_and_replaced(distributed, tmp_path):
    trainer, backend = distributed(_cfg(fragment_timeout=3.0), tmp_path)
    trainer.train(backend, total_steps=256)
    victim = backend.pids()[0]
    os.kill(victim, signal.SIGSTOP)  # alive but hung: its next fragment never comes
    try:
        start = time.monotonic()
        trainer.train(backend, total_steps=3 * 256)
        assert time.monotonic() - start < 60
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(victim, signal.SIGCONT)
    assert backend.fragment_errors.get("timeout", 0) >= 1
    wait_until(lambda: _pids(backend) and victim not in _pids(backend), 60, "a new process")
    assert trainer.progress.env_steps >= 3 * 256  # with one actor out, iterations are smaller


def _pids(backend) -> list[int]:
    try:
        return backend.pids()
    except ray.exceptions.RayActorError:  # still restarting
        return []


def test_a_stop_request_ends_the_wait_for_actors(distributed, tmp_path):
    trainer, backend = distributed(_cfg(fragment_timeout=600.0), tmp_path)
    pids = backend.pids()
    for pid in pids:
        os.kill(pid, signal.SIGSTOP)
    asked = time.monotonic() + 2.0
    backend.should_stop = lambda: time.monotonic() > asked
    try:
        start = time.monotonic()
        with pytest.raises(StopRequested):
            backend.collect(trainer.learner.weights(), trainer.learner.version)
        assert time.monotonic() - start < 10  # honoured within a few seconds
        backend.should_stop = lambda: time.monotonic() > asked + 3
        trainer.train(backend, total_steps=10 * 256)  # `train` ends cleanly on it
        assert trainer.progress.iteration == 0
    finally:
        for pid in pids:
            os.kill(pid, signal.SIGCONT)


def test_a_sampler_that_hangs_mid_run_stops_training_with_a_checkpoint(distributed, tmp_path):
    """The sampler stops answering between iterations: training ends with SamplerFailed within
    the timeouts, and the newest checkpoint loads (the final one when it could be written
    without the sampler; else the last periodic one, which is what the launcher then says)."""
    cfg = _cfg(sampler_timeout=2.0, fragment_timeout=10.0, max_fragment_errors=4)
    cfg.train.checkpoint_every = 1
    trainer, backend = distributed(cfg, tmp_path)
    trainer.train(backend, total_steps=2 * 256)
    done = trainer.progress.iteration
    assert checkpoint.load(tmp_path)["progress"]["iteration"] == done
    pid = ray.get(trainer.curriculum.handle.pid.remote())
    os.kill(pid, signal.SIGSTOP)
    try:
        start = time.monotonic()
        with pytest.raises(SamplerFailed, match="within 2 s"):
            trainer.train(backend, total_steps=50 * 256)
        assert time.monotonic() - start < 90
    finally:
        os.kill(pid, signal.SIGCONT)
    latest = checkpoint.checkpoint_dir(tmp_path) / checkpoint.LATEST
    assert checkpoint.verify(latest)
    state = checkpoint.load(tmp_path)
    assert done <= state["progress"]["iteration"] <= trainer.progress.iteration


def test_a_hung_sampler_is_a_sampler_failure(distributed, tmp_path):
    trainer, backend = distributed(_cfg(), tmp_path)
    handle = trainer.curriculum.handle
    pid = ray.get(handle.pid.remote())
    os.kill(pid, signal.SIGSTOP)
    try:
        with pytest.raises(SamplerFailed, match="within 2 s"):
            SamplerClient(handle, timeout=2.0).summary()
    finally:
        os.kill(pid, signal.SIGCONT)
