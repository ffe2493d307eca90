"""The sampler as a named Ray actor: restarted by Ray when its process dies, and then reloaded
from Redis. Calls to it are retried by Ray (at least once), which ingestion tolerates."""

from __future__ import annotations

import os

import ray
from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

from services.keys import RAY_NAMESPACE, sampler_actor_name
from services.sampler.service import SamplerService


@ray.remote(num_cpus=0, max_restarts=-1, max_task_retries=-1)
class SamplerActor(SamplerService):
    def __init__(
        self, config: dict, redis_url: str, run_id: str, clip: dict | None, owner: str | None
    ) -> None:
        restarted = ray.get_runtime_context().was_current_actor_reconstructed
        super().__init__(config, redis_url, run_id, restarted, clip=clip, owner=owner)

    def pid(self) -> int:
        return os.getpid()


def start_sampler(
    config: dict,
    redis_url: str,
    run_id: str,
    clip: dict | None = None,
    timeout: float = 120.0,
    owner: str | None = None,
):
    """Create the run's named sampler actor on the learner's node (it goes when the learner
    goes; a worker node leaving must not take it) and wait until it has loaded its state.
    `clip`: what an [L21] curriculum knows of the clip (`Spaces.clip_setup` of the run's method);
    `owner`: the learner's lease token, on which every write of the sampler is conditioned."""
    here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
    handle = SamplerActor.options(
        name=sampler_actor_name(run_id), namespace=RAY_NAMESPACE, scheduling_strategy=here
    ).remote(config, redis_url, run_id, clip, owner)
    ray.get(handle.pid.remote(), timeout=timeout)
    return handle
