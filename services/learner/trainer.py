"""The training loop: sample tasks, collect fragments, update PPO and V̄, refill S, checkpoint.

[WL19] Alg. 1 with the rollouts behind a `RolloutBackend`: `SerialBackend` (in-process, for
`--serial`) or `services.learner.ray_backend.RayBackend` (Ray rollout actors).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from paramimic.config import ExperimentConfig
from paramimic.curriculum import AdaptiveSampler, MarginalValue, TaskSpace
from paramimic.envs import make_env
from paramimic.rl.ppo import PPOLearner
from paramimic.rl.rollout import EpisodeSummary, Fragment, RolloutWorker, tasks_per_fragment
from services.learner import checkpoint


class RolloutBackend(Protocol):
    def collect(self, weights: dict[str, torch.Tensor], version: int) -> list[Fragment]: ...

    def stats(self) -> dict: ...

    def close(self) -> None: ...


class SerialBackend:
    """One in-process RolloutWorker stepping `actors.num_envs` environments: the same loop and
    the same seeds as Ray actor 0, so that both modes give the same fragments."""

    def __init__(
        self,
        cfg: ExperimentConfig,
        obs_dim: int,
        act_dim: int,
        next_tasks: Callable[[int], np.ndarray],
    ) -> None:
        m = cfg.actors.num_envs
        self.steps = cfg.actors.steps_per_fragment or math.ceil(cfg.ppo.num_steps / m)
        self.n_tasks = tasks_per_fragment(m, self.steps)
        self.next_tasks = next_tasks
        self.worker = RolloutWorker(
            lambda: make_env(cfg.character, cfg.task, cfg.env),
            m,
            obs_dim,
            act_dim,
            cfg.ppo.hidden_sizes,
            seed=cfg.train.seed + 1,
            worker_id=0,
        )

    def collect(self, weights: dict[str, torch.Tensor], version: int) -> list[Fragment]:
        self.worker.set_weights(weights, version)
        return [self.worker.collect(self.steps, self.next_tasks(self.n_tasks))]

    def stats(self) -> dict:
        return {"actors": 0}

    def close(self) -> None:
        pass


@dataclass
class Progress:
    iteration: int = 0
    env_steps: int = 0
    episodes: int = 0


class Trainer:
    def __init__(self, cfg: ExperimentConfig, run_dir: Path) -> None:
        self.cfg = cfg
        self.run_dir = Path(run_dir)
        probe = make_env(cfg.character, cfg.task, cfg.env)
        self.space: TaskSpace = probe.task_space
        self.obs_dim = probe.observation_space.shape[0]
        self.act_dim = probe.action_space.shape[0]
        torch.set_num_threads(cfg.train.torch_threads)
        seed = cfg.train.seed
        self.learner = PPOLearner(self.obs_dim, self.act_dim, cfg.ppo, seed=seed)
        cc = cfg.curriculum
        self.marginal = MarginalValue(
            self.space,
            cc.marginal_hidden,
            cc.marginal_lr,
            cc.mu_lr,
            cc.marginal_batch,
            seed=seed + 2,
        )
        self.sampler = AdaptiveSampler(
            self.space, cc.k, cc.n_mcmc, cc.chains, cc.burn_in, seed=seed + 3
        )
        self.progress = Progress()

    # --- state --------------------------------------------------------------------------------

    def state_dict(self) -> dict:
        return {
            "config": self.cfg.model_dump(mode="json"),
            "learner": self.learner.state_dict(),
            "marginal": self.marginal.to_state(),
            "sampler": self.sampler.to_state(),
            "progress": vars(self.progress).copy(),
            "obs_dim": self.obs_dim,
            "act_dim": self.act_dim,
        }

    def load_state_dict(self, state: dict) -> None:
        self.learner.load_state_dict(state["learner"])
        self.marginal.from_state(state["marginal"])
        self.sampler.from_state(state["sampler"])
        self.progress = Progress(**state["progress"])

    def save_checkpoint(self) -> Path:
        return checkpoint.save(self.run_dir, self.state_dict(), self.progress.iteration)

    # --- loop ---------------------------------------------------------------------------------

    def iteration(self, backend: RolloutBackend) -> dict:
        """One iteration of Alg. 1; returns its metrics."""
        cfg, it = self.cfg, self.progress.iteration
        t0 = time.perf_counter()
        if it % cfg.curriculum.p_mcmc == 0 and self.marginal.fitted:
            self.sampler.refill(self.marginal.predict, self.marginal.mu)  # l.3
        fragments = backend.collect(self.learner.weights(), self.learner.version)
        t_collect = time.perf_counter() - t0
        batch = self.learner.build_batch(fragments)
        metrics = self.learner.update(batch)  # l.21-23
        # l.24-26: as many minibatch steps on (a, v) pairs as PPO took on transitions
        gradient_steps = cfg.ppo.num_epochs * max(1, len(batch.obs) // cfg.ppo.minibatch_size)
        metrics["marginal_loss"] = self.marginal.fit(batch.tasks, batch.values, gradient_steps)
        episodes = [e for f in fragments for e in f.episodes]
        steps = sum(f.num_steps for f in fragments)
        self.progress.iteration += 1
        self.progress.env_steps += steps
        self.progress.episodes += len(episodes)
        elapsed = time.perf_counter() - t0
        metrics.update(episode_metrics(episodes))
        metrics.update(backend.stats())
        # versions between the policy that sampled each fragment and the one that was updated
        metrics["policy_lag"] = float(
            np.mean([self.learner.version - 1 - f.policy_version for f in fragments])
        )
        metrics.update(
            {
                "iteration": self.progress.iteration,
                "env_steps": self.progress.env_steps,
                "episodes_total": self.progress.episodes,
                "steps_per_second": steps / elapsed,
                "sample_steps_per_second": steps / max(t_collect, 1e-9),
                "mu": self.marginal.mu,
                "mean_step_reward": float(np.mean([f.rewards.mean() for f in fragments])),
                "time": time.time(),
            }
        )
        return metrics

    def train(
        self,
        backend: RolloutBackend,
        total_steps: int,
        on_metrics: Callable[[dict], None] | None = None,
        should_stop: Callable[[], bool] = lambda: False,
    ) -> None:
        """Iterate until `total_steps` env steps; checkpoint every K iterations and at the end."""
        log = (self.run_dir / "metrics.jsonl").open("a")
        try:
            while self.progress.env_steps < total_steps and not should_stop():
                m = self.iteration(backend)
                log.write(json.dumps(m) + "\n")
                log.flush()
                if on_metrics:
                    on_metrics(m)
                if self.progress.iteration % self.cfg.train.checkpoint_every == 0:
                    self.save_checkpoint()
        finally:
            log.close()
            self.save_checkpoint()


def episode_metrics(episodes: list[EpisodeSummary]) -> dict:
    if not episodes:
        return {"episodes": 0}
    return {
        "episodes": len(episodes),
        "mean_return": float(np.mean([e.ret for e in episodes])),
        "mean_length": float(np.mean([e.length for e in episodes])),
        "fall_percent": 100.0 * float(np.mean([e.fell for e in episodes])),
        "diverged": int(sum(e.diverged for e in episodes)),
    }
