"""The distributed training stack of one run on a connected Ray: the named sampler actor (state
in Redis), a Trainer that talks to it, and the rollout actors. Used by the launcher, the
benchmarks and the tests."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import ray

from paramimic.config import ExperimentConfig
from paramimic.training.method import method_for
from paramimic.training.trainer import Trainer
from services.actors.rollout_actor import spawner
from services.keys import sampler_actor_name
from services.learner.ray_backend import RayBackend, SamplerClient
from services.sampler.actor import start_sampler


@dataclass
class RayStack:
    trainer: Trainer
    backend: RayBackend
    sampler: ray.actor.ActorHandle
    run_id: str


@contextmanager
def ray_stack(
    cfg: ExperimentConfig,
    run_dir: Path,
    redis_url: str,
    run_id: str,
    actor_class=None,
    owner: str | None = None,
) -> Iterator[RayStack]:
    """Start the sampler and the rollout actors (`actor_class`: a Ray actor class with the
    RolloutActor interface, default RolloutActor; the fault tests inject through it); kill
    them on exit."""
    method = method_for(cfg)
    clip = method.spaces.clip_setup()  # what an [L21] curriculum needs of the clip
    sampler = start_sampler(cfg.model_dump(mode="json"), redis_url, run_id, clip, owner=owner)
    try:
        client = SamplerClient(sampler, cfg.actors.sampler_timeout)
        trainer = Trainer(cfg, run_dir, client, method)
        spawn = spawner(
            cfg, trainer.obs_dim, trainer.act_dim, sampler_actor_name(run_id), actor_class
        )
        backend = RayBackend(cfg, spawn)
        try:
            yield RayStack(trainer, backend, sampler, run_id)
        finally:
            backend.close()
    finally:
        ray.kill(sampler)
