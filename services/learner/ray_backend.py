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

Nodes come and go: the actors of a node that leaves the cluster are dropped from the pool (with
their fragments; Ray could not restart them there), and the iteration goes on with the others.
Each iteration tops the pool up to its size (`actors.num_actors`, or with `auto` one actor per
CPU of the cluster as it is now); a new actor joins the pool once it is up, so a node that joins
gets actors. Actors are spread over the nodes. Node losses and joins are kept as events for the
launcher to report.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import ray
import torch
from ray.exceptions import RayActorError

from paramimic.config import ExperimentConfig
from paramimic.curriculum.marginal_value import Layers
from paramimic.rl.rollout import Fragment, tasks_per_fragment
from services.actors.rollout_actor import RolloutActor

RETRY_PAUSE = 0.2  # seconds before asking a failed actor again
NODE_CHECK_EVERY = 1.0  # seconds between looks at which nodes are alive while waiting


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


@dataclass
class Member:
    """A rollout actor in the pool and the node it runs on."""

    handle: ray.actor.ActorHandle
    node_id: str
    node_ip: str


class RayBackend:
    """A pool of rollout actors that take their tasks from, and report their episodes to, the
    named sampler actor `sampler`."""

    def __init__(
        self,
        cfg: ExperimentConfig,
        obs_dim: int,
        act_dim: int,
        sampler: str,
    ) -> None:
        self.cfg = cfg
        self.mode = cfg.actors.mode
        self.obs_dim, self.act_dim, self.sampler = obs_dim, act_dim, sampler
        self.config = cfg.model_dump(mode="json")
        self.pool: dict[int, Member] = {}
        self.joining: dict[ray.ObjectRef, tuple[int, ray.actor.ActorHandle]] = {}
        self.pending: dict[ray.ObjectRef, int] = {}  # in-flight fragment -> actor id
        self.weights_ref: list[ray.ObjectRef] = []
        self.version = -1
        self.restarts = 0
        self.dropped = 0
        self.lost = 0  # actors dropped with their node
        self.failing: set[int] = set()
        self.nodes_seen: set[str] = set()
        self.events: list[tuple[str, str, dict]] = []
        self.next_id = 0
        self.checked_at = 0.0
        self._spawn(resolve_num_actors(cfg.actors.num_actors))
        # the first pool: every actor that comes up within lost_timeout (the others join later)
        self._admit(timeout=cfg.actors.lost_timeout)
        self.events.clear()  # the first nodes are not news

    @property
    def num_actors(self) -> int:
        return len(self.pool)

    @property
    def actors(self) -> list[ray.actor.ActorHandle]:
        return [m.handle for m in self.pool.values()]

    @property
    def steps(self) -> int:
        """Steps per fragment: ppo.num_steps split over the actors now in the pool."""
        n, m = max(1, len(self.pool)), self.cfg.actors.num_envs
        return self.cfg.actors.steps_per_fragment or max(1, -(-self.cfg.ppo.num_steps // (n * m)))

    @property
    def n_tasks(self) -> int:
        return tasks_per_fragment(self.cfg.actors.num_envs, self.steps)

    def _spawn(self, n: int) -> None:
        for _ in range(n):
            i, self.next_id = self.next_id, self.next_id + 1
            handle = RolloutActor.options(scheduling_strategy="SPREAD").remote(
                self.config,
                self.obs_dim,
                self.act_dim,
                self.cfg.train.seed + 1 + i,
                i,
                self.sampler,
            )
            self.joining[handle.node.remote()] = (i, handle)

    def _admit(self, timeout: float = 0.0) -> None:
        """Move the actors that are up (within `timeout` seconds, if all are not yet) from
        `joining` into the pool."""
        if not self.joining:
            return
        refs = list(self.joining)
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        for ref in ready:
            i, handle = self.joining.pop(ref)
            try:
                node_id, node_ip = ray.get(ref)
            except RayActorError:
                continue  # died while starting; the next top-up replaces it
            self.pool[i] = Member(handle, node_id, node_ip)
            if node_id not in self.nodes_seen:
                self.nodes_seen.add(node_id)
                self.events.append(
                    ("node_joined", f"node {node_ip} joined: rollout actors start there", {
                        "node_id": node_id, "node_ip": node_ip})
                )  # fmt: skip

    def wait_for_actors(self, n: int, timeout: float) -> int:
        """Admit joining actors until `n` are in the pool or `timeout` s pass; the pool size."""
        deadline = time.monotonic() + timeout
        while len(self.pool) < n and self.joining and time.monotonic() < deadline:
            self._admit(timeout=min(1.0, max(0.0, deadline - time.monotonic())))
        return len(self.pool)

    def _top_up(self) -> None:
        """Start actors up to the pool size (auto: the cluster's CPUs now); admit those up."""
        want = resolve_num_actors(self.cfg.actors.num_actors)
        self._spawn(want - len(self.pool) - len(self.joining))
        self._admit()

    def _check_nodes(self, force: bool = False) -> None:
        """Drop the actors whose node has left the cluster, with their in-flight fragments."""
        now = time.monotonic()
        if not force and now - self.checked_at < NODE_CHECK_EVERY:
            return
        self.checked_at = now
        alive = {n["NodeID"] for n in ray.nodes() if n["Alive"]}
        gone: dict[str, list[int]] = {}
        for i, m in self.pool.items():
            if m.node_id not in alive:
                gone.setdefault(m.node_id, []).append(i)
        for node_id, ids in gone.items():
            ip = self.pool[ids[0]].node_ip
            dropped = 0
            for i in ids:
                member = self.pool.pop(i)
                self.failing.discard(i)
                for ref in [r for r, j in self.pending.items() if j == i]:
                    del self.pending[ref]
                    dropped += 1
                # Ray would otherwise keep it restarting until some node has a CPU for it
                ray.kill(member.handle, no_restart=True)
            self.lost += len(ids)
            self.dropped += dropped
            self.nodes_seen.discard(node_id)  # a node that comes back is news again
            self.events.append(
                ("node_lost", f"node {ip} left: {len(ids)} rollout actor(s) and {dropped} "
                 f"fragment(s) dropped; training goes on with {len(self.pool)} actor(s)",
                 {"node_id": node_id, "node_ip": ip, "actors": len(ids), "fragments": dropped})
            )  # fmt: skip

    def _request(self, i: int) -> None:
        ref = self.pool[i].handle.sample.remote(
            self.weights_ref, self.version, self.steps, self.n_tasks
        )
        self.pending[ref] = i

    def collect(self, weights: dict[str, torch.Tensor], version: int) -> list[Fragment]:
        """Fragments totalling about ppo.num_steps transitions (one per live actor)."""
        self._check_nodes(force=True)
        self._top_up()
        if version != self.version:
            self.weights_ref = [ray.put(weights)]
            self.version = version
        fragments: list[Fragment] = []
        answered: set[int] = set()  # actors that delivered or failed this iteration
        lost_since: float | None = None
        while not fragments or not answered >= set(self.pool):
            busy = set(self.pending.values())
            for i in self.pool:
                if i not in busy and i not in answered:
                    self._request(i)
            waited = 0.0 if lost_since is None else time.monotonic() - lost_since
            if not fragments and waited > self.cfg.actors.lost_timeout:
                raise AllActorsLost(
                    f"no rollout actor delivered a fragment for "
                    f"{self.cfg.actors.lost_timeout:.0f} s"
                )
            if not self.pending:  # no actor left: wait for one to join
                lost_since = lost_since or time.monotonic()
                time.sleep(RETRY_PAUSE)
                self._check_nodes()
                self._top_up()
                continue
            # One fragment per actor and iteration: an answered actor's next fragment (pipelined,
            # or a re-request after a failure) waits for the next iteration, unless nothing
            # arrived at all.
            waiting = [r for r, i in self.pending.items() if i not in answered]
            ready, _ = ray.wait(waiting or list(self.pending), num_returns=1, timeout=1.0)
            if not ready:
                self._check_nodes()
                continue
            ref = ready[0]
            i = self.pending.pop(ref)
            answered.add(i)
            try:
                fragment = ray.get(ref)
            except RayActorError:
                lost_since = lost_since or time.monotonic()
                self._check_nodes(force=True)
                if i not in self.pool:
                    continue  # lost with its node
                # The actor's process died: its fragment is dropped and Ray restarts it. Ask it
                # again at once; the call waits at Ray until the new process takes it.
                if i not in self.failing:
                    self.restarts += 1
                    self.failing.add(i)
                self.dropped += 1
                time.sleep(RETRY_PAUSE)  # do not spin on an actor that keeps failing
                self._request(i)
                continue
            self.failing.discard(i)
            fragments.append(fragment)
            if self.mode == "pipelined":
                self._request(i)  # sample the next fragment while the learner updates
        return fragments

    def take_events(self) -> list[tuple[str, str, dict]]:
        """(kind, message, data) of the node losses and joins since the last call."""
        events, self.events = self.events, []
        return events

    def stats(self) -> dict:
        return {
            "actors": len(self.pool),
            "nodes": len({m.node_id for m in self.pool.values()}),
            "actor_restarts": self.restarts,
            "actors_lost": self.lost,
            "dropped_fragments": self.dropped,
        }

    def pids(self) -> list[int]:
        return ray.get([m.handle.pid.remote() for m in self.pool.values()])

    def close(self) -> None:
        for ref in self.pending:
            ray.cancel(ref, force=False)
        self.pending.clear()
        for handle in self.actors + [h for _, h in self.joining.values()]:
            ray.kill(handle)
        self.pool.clear()
        self.joining.clear()
