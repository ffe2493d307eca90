"""The rollout actor: a Ray shell around paramimic.rl.rollout.RolloutWorker.

It fetches the policy weights from the object store only when their version changes, asks the
sampler for the tasks of the episodes that will start in the fragment, runs the fragment with the
library's stepping loop, reports the finished episodes to the sampler and returns the fragment.
A diverging simulation ends its episode inside the env. Any other exception in `sample` (an env
that raises, a sampler that does not answer: `SamplerUnavailable`) fails that call only; the
learner drops the fragment, counts it under its reason and asks again.
"""

from __future__ import annotations

import os
import resource
import time

import numpy as np
import ray
from ray.exceptions import GetTimeoutError, RayActorError

from paramimic.config import ExperimentConfig
from paramimic.envs import env_for
from paramimic.messages import TaskDeal
from paramimic.rl.rollout import Fragment, RolloutWorker, horizon_of
from services.keys import RAY_NAMESPACE, SamplerUnavailable


@ray.remote(num_cpus=1, max_restarts=-1)
class RolloutActor:
    def __init__(
        self,
        config: dict,
        obs_dim: int,
        act_dim: int,
        seed: int,
        worker_id: int,
        sampler: str | None = None,
    ) -> None:
        cfg = ExperimentConfig.model_validate(config)
        # the named sampler actor (looked up by name: a handle argument would live in the object
        # store, which a restarted actor cannot rely on)
        self.sampler = None if sampler is None else ray.get_actor(sampler, namespace=RAY_NAMESPACE)
        self.source = f"actor{worker_id}"
        self.sampler_timeout = cfg.actors.sampler_timeout
        self.restarted = ray.get_runtime_context().was_current_actor_reconstructed
        if self.restarted:  # a restarted actor must not replay the episodes it already ran
            seed = int(np.random.SeedSequence([seed, os.getpid()]).generate_state(1)[0])
        self.worker = RolloutWorker(
            lambda: env_for(cfg),
            cfg.actors.num_envs,
            obs_dim,
            act_dim,
            seed=seed,
            worker_id=worker_id,
            # episode ids stay unique across restarts and resumed runs (the sampler dedupes by id)
            id_prefix=os.urandom(4).hex() + "-",
            horizon=horizon_of(cfg),
        )

    def pid(self) -> int:
        return os.getpid()

    def node(self) -> tuple[str, str]:
        """(Ray node id, node IP) of the node this actor runs on."""
        return ray.get_runtime_context().get_node_id(), ray.util.get_node_ip_address()

    def peak_rss_mb(self) -> float:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    def sample(
        self,
        weights: list[ray.ObjectRef],
        version: int,
        num_steps: int,
        tasks: int | np.ndarray | TaskDeal,
        use_policy: bool = True,
    ) -> Fragment:
        """One fragment whose episodes take `tasks` (an array or a deal) or that many tasks
        from the sampler (a deal: with [L21] the motions m_a to imitate). `weights` is a
        one-element list so that Ray does not fetch the (unchanged) weights on every call:
        they are read only when `version` is new."""
        if version != self.worker.policy_version:
            self.worker.set_weights(ray.get(weights[0], timeout=self.sampler_timeout), version)
        if isinstance(tasks, int):
            n = tasks
            tasks = self._ask_sampler(lambda: self.sampler.next_deal.remote(n, self.source))
        fragment = self.worker.collect(num_steps, tasks, use_policy)
        if self.sampler is not None:  # acknowledged before the learner sees the fragment
            self._ask_sampler(lambda: self.sampler.ingest.remote(fragment.episodes))
        return fragment

    def _ask_sampler(self, call):
        """The sampler's answer to `call()` within actors.sampler_timeout; a sampler that is
        restarting is asked again (ingestion is idempotent by episode id). Else
        SamplerUnavailable: the learner files the dropped fragment under the sampler."""
        deadline = time.monotonic() + self.sampler_timeout
        while True:
            try:
                return ray.get(call(), timeout=max(deadline - time.monotonic(), 0.1))
            except (GetTimeoutError, RayActorError) as e:
                if isinstance(e, GetTimeoutError) or time.monotonic() > deadline:
                    raise SamplerUnavailable(
                        f"the sampler did not answer within {self.sampler_timeout:.0f} s: "
                        f"{type(e).__name__}"
                    ) from None
                time.sleep(0.5)  # restarting: Ray brings it back and it reloads from Redis


def spawner(cfg: ExperimentConfig, obs_dim: int, act_dim: int, sampler: str, actor_class=None):
    """actor id i -> a started rollout actor (spread over the nodes) whose tasks come from the
    named sampler actor; its seed follows from the run's seed and i. `actor_class`: RolloutActor
    or a Ray actor class derived from it."""
    config = cfg.model_dump(mode="json")
    actor_class = actor_class or RolloutActor

    def spawn(i: int) -> ray.actor.ActorHandle:
        seed = cfg.train.seed + 1 + i
        return actor_class.options(scheduling_strategy="SPREAD").remote(
            config, obs_dim, act_dim, seed, i, sampler
        )

    return spawn
