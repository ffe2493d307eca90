"""The pool of rollout actors: who is in it, on which node, and keeping it at its size.

Actors are spread over the nodes (the launcher's `spawn` decides how one is started). A new actor
joins the pool once it answers; each `top_up` starts actors up to the pool size
(`actors.num_actors`, or with `auto` one per CPU of the cluster as it is now), so a node that
joins gets actors. The actors of a node that leaves the cluster are dropped from the pool (Ray
could not restart them there). Node joins are kept as events for the launcher.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import ray
from ray.exceptions import RayActorError

READY_TIMEOUT = 30.0  # seconds for a ray.get of an object ray.wait reported ready

NODE_CHECK_EVERY = 1.0  # seconds between looks at which nodes are alive while waiting

Spawn = Callable[[int], ray.actor.ActorHandle]  # actor id -> a started rollout actor


def resolve_num_actors(setting: int | str) -> int:
    if setting != "auto":
        return int(setting)
    # One actor per CPU: Ray runs its workers at a lower priority than the learner, so the PPO
    # update still gets a core when it needs one (measured in benchmarks/throughput.py).
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


@dataclass
class Member:
    """A rollout actor in the pool and the node it runs on."""

    handle: ray.actor.ActorHandle
    node_id: str
    node_ip: str


@dataclass
class LostNode:
    node_id: str
    node_ip: str
    actor_ids: list[int]


class ActorPool:
    def __init__(self, spawn: Spawn, size: int | str, admit_timeout: float) -> None:
        self.spawn_actor, self.size = spawn, size
        self.members: dict[int, Member] = {}
        self.joining: dict[ray.ObjectRef, tuple[int, ray.actor.ActorHandle]] = {}
        self.nodes_seen: set[str] = set()
        self.events: list[tuple[str, str, dict]] = []
        self.lost = 0  # actors dropped with their node
        self.next_id = 0
        self.checked_at = 0.0
        self._spawn(resolve_num_actors(size))
        # the first pool: every actor that comes up within admit_timeout (the others join later)
        self.admit(timeout=admit_timeout)
        self.events.clear()  # the first nodes are not news

    def __len__(self) -> int:
        return len(self.members)

    def __contains__(self, i: int) -> bool:
        return i in self.members

    def ids(self) -> list[int]:
        return list(self.members)

    def handle(self, i: int) -> ray.actor.ActorHandle:
        return self.members[i].handle

    @property
    def handles(self) -> list[ray.actor.ActorHandle]:
        return [m.handle for m in self.members.values()]

    @property
    def nodes(self) -> int:
        return len({m.node_id for m in self.members.values()})

    def _spawn(self, n: int) -> None:
        for _ in range(n):
            i, self.next_id = self.next_id, self.next_id + 1
            handle = self.spawn_actor(i)
            self.joining[handle.node.remote()] = (i, handle)

    def admit(self, timeout: float = 0.0) -> None:
        """Move the actors that are up (within `timeout` seconds, if all are not yet) from
        `joining` into the pool."""
        if not self.joining:
            return
        refs = list(self.joining)
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        for ref in ready:
            i, handle = self.joining.pop(ref)
            try:
                node_id, node_ip = ray.get(ref, timeout=READY_TIMEOUT)  # ready: at once
            except RayActorError:
                continue  # died while starting; the next top-up replaces it
            self.members[i] = Member(handle, node_id, node_ip)
            if node_id not in self.nodes_seen:
                self.nodes_seen.add(node_id)
                message = f"node {node_ip} joined: rollout actors start there"
                self.events.append(
                    ("node_joined", message, {"node_id": node_id, "node_ip": node_ip})
                )

    def wait_for(self, n: int, timeout: float) -> int:
        """Admit joining actors until `n` are in the pool or `timeout` s pass; the pool size."""
        deadline = time.monotonic() + timeout
        while len(self.members) < n and self.joining and time.monotonic() < deadline:
            self.admit(timeout=min(1.0, max(0.0, deadline - time.monotonic())))
        return len(self.members)

    def top_up(self) -> None:
        """Start actors up to the pool size (auto: the cluster's CPUs now); admit those up."""
        want = resolve_num_actors(self.size)
        self._spawn(want - len(self.members) - len(self.joining))
        self.admit()

    def drop_lost_nodes(self, force: bool = False) -> list[LostNode]:
        """Drop the actors whose node has left the cluster (looked at most every second unless
        `force`); returns the nodes lost with their actors' ids, whose work the caller drops."""
        now = time.monotonic()
        if not force and now - self.checked_at < NODE_CHECK_EVERY:
            return []
        self.checked_at = now
        alive = {n["NodeID"] for n in ray.nodes() if n["Alive"]}
        gone: dict[str, list[int]] = {}
        for i, m in self.members.items():
            if m.node_id not in alive:
                gone.setdefault(m.node_id, []).append(i)
        lost = []
        for node_id, ids in gone.items():
            lost.append(LostNode(node_id, self.members[ids[0]].node_ip, ids))
            for i in ids:
                # Ray would otherwise keep it restarting until some node has a CPU for it
                ray.kill(self.members.pop(i).handle, no_restart=True)
            self.lost += len(ids)
            self.nodes_seen.discard(node_id)  # a node that comes back is news again
        return lost

    def take_events(self) -> list[tuple[str, str, dict]]:
        """(kind, message, data) of the nodes that joined since the last call."""
        events, self.events = self.events, []
        return events

    def pids(self) -> list[int]:
        return ray.get([m.handle.pid.remote() for m in self.members.values()], timeout=60)

    def close(self) -> None:
        for handle in self.handles + [h for _, h in self.joining.values()]:
            ray.kill(handle)
        self.members.clear()
        self.joining.clear()
