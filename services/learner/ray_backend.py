"""Rollouts on Ray: N RolloutActors, weights put once per iteration, fragments gathered with
`ray.wait` as they arrive.

- sync: every iteration sends the new weights and waits for all N fragments.
- pipelined: as soon as an actor's fragment arrives it is asked for the next one with the
  weights it had, so sampling overlaps the PPO update; those fragments are one policy version
  behind and the PPO ratio π/π_behaviour (their recorded log-probs) corrects for it.

An actor whose process dies is restarted by Ray (max_restarts=-1); its lost fragment is dropped,
the restart is counted, the iteration goes on with the other actors' fragments, and the actor is
asked again at once (its answer, when it is back, joins a later iteration; the PPO ratio corrects
its version lag). If no actor delivers for `actors.lost_timeout` seconds, `AllActorsLost` is
raised so that the learner can checkpoint and exit.
"""

from __future__ import annotations

import time

import numpy as np
import ray
import torch
from ray.exceptions import RayActorError

from paramimic.config import ExperimentConfig
from paramimic.curriculum.marginal_value import Layers
from paramimic.rl.rollout import Fragment, tasks_per_fragment
from services.actors.rollout_actor import RolloutActor

RETRY_PAUSE = 0.2  # seconds before asking a failed actor again


class AllActorsLost(RuntimeError):
    pass


def resolve_num_actors(setting: int | str) -> int:
    if setting != "auto":
        return int(setting)
    # One actor per CPU: Ray runs its workers at a lower priority than the learner, so the PPO
    # update still gets a core when it needs one (measured in benchmarks/throughput.py).
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


class SamplerClient:
    """The learner's view of the sampler actor: the calls of a local curriculum."""

    def __init__(self, handle: ray.actor.ActorHandle) -> None:
        self.handle = handle

    def next_tasks(self, n: int) -> np.ndarray:
        return ray.get(self.handle.next_tasks.remote(n, "learner"))

    def next_deal(self, n: int) -> dict:
        return ray.get(self.handle.next_deal.remote(n, "learner"))

    def ingest(self, episodes: list[dict]) -> int:
        return ray.get(self.handle.ingest.remote(episodes))

    def elite_data(self) -> tuple[np.ndarray, np.ndarray]:
        return ray.get(self.handle.elite_data.remote())

    def update_motion(self, layers, version: int, loss: float | None, stage: str) -> None:
        ray.get(self.handle.update_motion.remote(layers, version, loss, stage))

    def update_marginal(self, layers: Layers, mu: float, iteration: int, refill: bool) -> None:
        ray.get(self.handle.update_marginal.remote(layers, mu, iteration, refill))

    def set_k(self, k: float) -> None:
        ray.get(self.handle.set_k.remote(k))

    def summary(self) -> dict:
        return ray.get(self.handle.summary.remote())

    def to_state(self) -> dict:
        return ray.get(self.handle.to_state.remote())

    def from_state(self, state: dict) -> None:
        ray.get(self.handle.from_state.remote(state))


class RayBackend:
    """N rollout actors that take their tasks from, and report their episodes to, the named
    sampler actor `sampler`."""

    def __init__(
        self,
        cfg: ExperimentConfig,
        obs_dim: int,
        act_dim: int,
        sampler: str,
    ) -> None:
        self.cfg = cfg
        self.mode = cfg.actors.mode
        n = resolve_num_actors(cfg.actors.num_actors)
        m = cfg.actors.num_envs
        self.steps = cfg.actors.steps_per_fragment or max(1, -(-cfg.ppo.num_steps // (n * m)))
        self.n_tasks = tasks_per_fragment(m, self.steps)
        config = cfg.model_dump(mode="json")
        self.actors = [
            RolloutActor.remote(config, obs_dim, act_dim, cfg.train.seed + 1 + i, i, sampler)
            for i in range(n)
        ]
        self.pending: dict[ray.ObjectRef, int] = {}  # in-flight fragment -> actor index
        self.weights_ref: list[ray.ObjectRef] = []
        self.version = -1
        self.restarts = 0
        self.dropped = 0
        self.failing: set[int] = set()

    @property
    def num_actors(self) -> int:
        return len(self.actors)

    def _request(self, i: int) -> None:
        ref = self.actors[i].sample.remote(self.weights_ref, self.version, self.steps, self.n_tasks)
        self.pending[ref] = i

    def collect(self, weights: dict[str, torch.Tensor], version: int) -> list[Fragment]:
        """Fragments totalling about ppo.num_steps transitions (one per live actor)."""
        if version != self.version:
            self.weights_ref = [ray.put(weights)]
            self.version = version
        busy = set(self.pending.values())
        for i in range(len(self.actors)):
            if i not in busy:
                self._request(i)
        fragments: list[Fragment] = []
        answered: set[int] = set()  # actors that delivered or failed this iteration
        lost_since: float | None = None
        while len(answered) < len(self.actors) or not fragments:
            waited = 0.0 if lost_since is None else time.monotonic() - lost_since
            if not fragments and waited > self.cfg.actors.lost_timeout:
                raise AllActorsLost(
                    f"no rollout actor delivered a fragment for "
                    f"{self.cfg.actors.lost_timeout:.0f} s"
                )
            # One fragment per actor and iteration: an answered actor's next fragment (pipelined,
            # or a re-request after a failure) waits for the next iteration, unless nothing
            # arrived at all.
            waiting = [r for r, i in self.pending.items() if i not in answered]
            ready, _ = ray.wait(waiting or list(self.pending), num_returns=1, timeout=1.0)
            if not ready:
                continue
            ref = ready[0]
            i = self.pending.pop(ref)
            answered.add(i)
            try:
                fragment = ray.get(ref)
            except RayActorError:
                # The actor's process died: its fragment is dropped and Ray restarts it. Ask it
                # again at once; the call waits at Ray until the new process takes it.
                if i not in self.failing:
                    self.restarts += 1
                    self.failing.add(i)
                self.dropped += 1
                lost_since = lost_since or time.monotonic()
                time.sleep(RETRY_PAUSE)  # do not spin on an actor that keeps failing
                self._request(i)
                continue
            self.failing.discard(i)
            fragments.append(fragment)
            if self.mode == "pipelined":
                self._request(i)  # sample the next fragment while the learner updates
        return fragments

    def stats(self) -> dict:
        return {
            "actors": len(self.actors),
            "actor_restarts": self.restarts,
            "dropped_fragments": self.dropped,
        }

    def pids(self) -> list[int]:
        return ray.get([a.pid.remote() for a in self.actors])

    def close(self) -> None:
        for ref in self.pending:
            ray.cancel(ref, force=False)
        self.pending.clear()
        for a in self.actors:
            ray.kill(a)
        self.actors = []
