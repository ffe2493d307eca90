"""The rollout actor: a Ray shell around paramimic.rl.rollout.RolloutWorker.

It fetches the policy weights from the object store only when their version changes, runs one
fragment with the library's stepping loop, and returns it. A diverging simulation ends its
episode inside the env; nothing here can kill the actor but the process dying.
"""

from __future__ import annotations

import os
import resource

import numpy as np
import ray
import torch

from paramimic.config import ExperimentConfig
from paramimic.envs import make_env
from paramimic.rl.rollout import Fragment, RolloutWorker


@ray.remote(num_cpus=1, max_restarts=-1)
class RolloutActor:
    def __init__(self, config: dict, obs_dim: int, act_dim: int, seed: int, worker_id: int) -> None:
        torch.set_num_threads(1)
        cfg = ExperimentConfig.model_validate(config)
        self.restarted = ray.get_runtime_context().was_current_actor_reconstructed
        if self.restarted:  # a restarted actor must not replay the episodes it already ran
            seed = int(np.random.SeedSequence([seed, os.getpid()]).generate_state(1)[0])
        self.worker = RolloutWorker(
            lambda: make_env(cfg.character, cfg.task, cfg.env),
            cfg.actors.num_envs,
            obs_dim,
            act_dim,
            cfg.ppo.hidden_sizes,
            seed=seed,
            worker_id=worker_id,
        )
        self.restarted = ray.get_runtime_context().was_current_actor_reconstructed

    def pid(self) -> int:
        return os.getpid()

    def peak_rss_mb(self) -> float:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    def sample(
        self,
        weights: list[ray.ObjectRef],
        version: int,
        num_steps: int,
        tasks: np.ndarray,
        use_policy: bool = True,
    ) -> Fragment:
        """One fragment. `weights` is a one-element list so that Ray does not fetch the
        (unchanged) weights on every call: they are read only when `version` is new."""
        if version != self.worker.policy_version:
            self.worker.set_weights(ray.get(weights[0]), version)
        return self.worker.collect(num_steps, tasks, use_policy)
