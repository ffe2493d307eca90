"""Rollouts on Ray: fragments gathered from a pool of rollout actors with `ray.wait`, the weights
put once per iteration.

- sync: every iteration sends the new weights and waits for a fragment from every actor.
- pipelined: as soon as an actor's fragment arrives it is asked for the next one with the
  weights it had, so sampling overlaps the PPO update; those fragments are one policy version
  behind and the PPO ratio π/π_behaviour (their recorded log-probs) corrects for it.

An actor whose process dies is restarted by Ray (max_restarts=-1); its lost fragment is dropped,
the restart is counted, the iteration goes on with the other actors' fragments, and the actor is
asked again at once (its answer, when it is back, joins a later iteration; the PPO ratio corrects
its version lag). A fragment Ray itself fails (a full disk or object store, an object or error
that does not deserialize) is dropped the same way, as `ray_error`. If no actor delivers for
`actors.lost_timeout` seconds, `AllActorsLost` is raised so that the learner can checkpoint and
exit. Which actors are in the pool, on which nodes, is `ActorPool`'s business (`actor_pool.py`).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import ray
from ray.exceptions import (
    GetTimeoutError,
    ObjectLostError,
    RayActorError,
    RayError,
    RayTaskError,
)

from paramimic.config import ExperimentConfig
from paramimic.rl.rollout import Fragment, steps_per_fragment, tasks_per_fragment
from paramimic.training.trainer import StopRequested
from services.keys import SamplerUnavailable
from services.learner.actor_pool import (
    READY_TIMEOUT,
    ActorPool,
    LostNode,
    Spawn,
    resolve_num_actors,
)

RETRY_PAUSE = 0.2  # seconds before asking a failed actor again

__all__ = [
    "AllActorsLost",
    "ClusterFailing",
    "FragmentsFailing",
    "RayBackend",
    "SamplerClient",
    "SamplerFailed",
    "StopRequested",
    "resolve_num_actors",
]


class AllActorsLost(RuntimeError):
    pass


class FragmentsFailing(RuntimeError):
    """actors.max_fragment_errors fragment errors in a row: a persistent cause."""


class ClusterFailing(RuntimeError):
    """Ray refused to store the policy weights (object store full, disk full) for
    `PUT_PATIENCE` seconds."""


PUT_PATIENCE = 60.0  # seconds of retries of a refused ray.put (spilling may free the store)


class SamplerFailed(RuntimeError):
    """The sampler actor did not answer the learner within actors.sampler_timeout."""


class SamplerClient:
    """The learner's view of the sampler actor: every call of the curriculum (`Curriculum` and
    its capability Protocols in `paramimic.training.curriculum`) forwarded to the actor and
    answered within `timeout` s (Ray restarts a dead sampler and retries the call meanwhile),
    or `SamplerFailed`."""

    SOURCED = frozenset({"next_tasks", "next_deal"})  # the sampler logs who asked for tasks

    def __init__(self, handle: ray.actor.ActorHandle, timeout: float = 60.0) -> None:
        self.handle = handle
        self.timeout = timeout

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        getattr(self.handle, name)  # AttributeError for what the sampler does not answer
        source = ("learner",) if name in self.SOURCED else ()
        return lambda *args: self._get(name, *args, *source)

    def _get(self, name: str, *args):
        try:
            return ray.get(getattr(self.handle, name).remote(*args), timeout=self.timeout)
        except (GetTimeoutError, RayActorError) as e:
            raise SamplerFailed(
                f"the sampler actor did not answer {name} within {self.timeout:.0f} s "
                f"({type(e).__name__})"
            ) from None
        except RayTaskError:
            raise  # the sampler's own error, with its traceback
        except RayError as e:  # Ray itself failed the call: disk, object store, serialization
            raise SamplerFailed(
                f"Ray failed the sampler's {name}: {type(e).__name__}: {_first_line(e)}"
            ) from None


class RayBackend:
    """Gathers fragments from a pool of rollout actors started by `spawn` (the launcher's: they
    take their tasks from, and report their episodes to, the sampler actor)."""

    def __init__(self, cfg: ExperimentConfig, spawn: Spawn) -> None:
        self.cfg = cfg
        self.mode = cfg.actors.mode
        self.pool = ActorPool(spawn, cfg.actors.num_actors, admit_timeout=cfg.actors.lost_timeout)
        self.pending: dict[ray.ObjectRef, int] = {}  # in-flight fragment -> actor id
        self.sent: dict[ray.ObjectRef, float] = {}  # in-flight fragment -> when it was asked for
        self.fragment_errors: dict[str, int] = {}  # reason -> fragments dropped for it
        self.errors_in_a_row = 0
        self.should_stop: Callable[[], bool] = lambda: False  # the launcher's stop flag
        self.weights_ref: list[ray.ObjectRef] = []
        self.version = -1
        self.restarts = 0
        self.dropped = 0
        self.failing: set[int] = set()
        self.events: list[tuple[str, str, dict]] = []

    @property
    def num_actors(self) -> int:
        return len(self.pool)

    @property
    def actors(self) -> list[ray.actor.ActorHandle]:
        return self.pool.handles

    @property
    def steps(self) -> int:
        """Steps per fragment: ppo.num_steps split over the actors now in the pool."""
        return steps_per_fragment(self.cfg.actors, self.cfg.ppo.num_steps, len(self.pool))

    @property
    def n_tasks(self) -> int:
        return tasks_per_fragment(self.cfg.actors.num_envs, self.steps)

    def wait_for_actors(self, n: int, timeout: float) -> int:
        """Admit joining actors until `n` are in the pool or `timeout` s pass; the pool size."""
        return self.pool.wait_for(n, timeout)

    def _check_nodes(self, force: bool = False) -> None:
        """Forget the in-flight fragments of the actors whose node left the cluster."""
        for node in self.pool.drop_lost_nodes(force):
            self._drop_node(node)

    def _drop_node(self, node: LostNode) -> None:
        gone = [r for r, i in self.pending.items() if i in node.actor_ids]
        for ref in gone:
            self._forget(ref)
        self.failing -= set(node.actor_ids)
        self.dropped += len(gone)
        n = len(node.actor_ids)
        self.events.append(
            ("node_lost", f"node {node.node_ip} left: {n} rollout actor(s) and {len(gone)} "
             f"fragment(s) dropped; training goes on with {len(self.pool)} actor(s)",
             {"node_id": node.node_id, "node_ip": node.node_ip, "actors": n,
              "fragments": len(gone)})
        )  # fmt: skip

    def _request(self, i: int) -> None:
        ref = self.pool.handle(i).sample.remote(
            self.weights_ref, self.version, self.steps, self.n_tasks
        )
        self.pending[ref] = i
        self.sent[ref] = time.monotonic()

    def _forget(self, ref: ray.ObjectRef) -> int:
        self.sent.pop(ref, None)
        return self.pending.pop(ref)

    def collect(self, weights: dict[str, np.ndarray], version: int) -> list[Fragment]:
        """Fragments totalling about ppo.num_steps transitions (one per live actor)."""
        self._check_nodes(force=True)
        self.pool.top_up()
        if version != self.version:
            self.weights_ref = [self._put(weights)]
            self.version = version
        fragments: list[Fragment] = []
        answered: set[int] = set()  # actors that delivered or failed this iteration
        lost_since: float | None = None
        while not fragments or not answered >= set(self.pool.ids()):
            if self.should_stop():
                raise StopRequested
            self._request_idle(answered)
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
                self.pool.top_up()
                continue
            ref = self._next_ready(answered)
            if ref is None:
                self._check_nodes()
                self._kill_hung(answered)
                continue
            i = self._forget(ref)
            answered.add(i)
            fragment = self._receive(ref, i)
            if fragment is None:
                lost_since = lost_since or time.monotonic()
                continue
            fragments.append(fragment)
            if self.mode == "pipelined":
                self._request(i)  # sample the next fragment while the learner updates
        return fragments

    def _put(self, weights: dict[str, np.ndarray]) -> ray.ObjectRef:
        """The weights in Ray's object store, retried while Ray refuses them (a full store may
        spill; a full disk may be cleared); ClusterFailing after PUT_PATIENCE seconds."""
        start = time.monotonic()
        while True:
            try:
                return ray.put(weights)
            except RayError as e:
                if time.monotonic() - start > PUT_PATIENCE:
                    raise ClusterFailing(
                        f"Ray refused the policy weights for {PUT_PATIENCE:.0f} s: "
                        f"{type(e).__name__}: {_first_line(e)}"
                    ) from None
                if self.should_stop():
                    raise StopRequested from None
                time.sleep(1.0)

    def _request_idle(self, answered: set[int]) -> None:
        """Ask every pool actor that has no fragment in flight and has not answered yet."""
        busy = set(self.pending.values())
        for i in self.pool.ids():
            if i not in busy and i not in answered:
                self._request(i)

    def _next_ready(self, answered: set[int]) -> ray.ObjectRef | None:
        """The next finished fragment, waiting up to 1 s. One fragment per actor and iteration:
        an answered actor's next fragment (pipelined, or a re-request after a failure) waits for
        the next iteration, unless nothing arrived at all."""
        waiting = [r for r, i in self.pending.items() if i not in answered]
        ready, _ = ray.wait(waiting or list(self.pending), num_returns=1, timeout=1.0)
        return ready[0] if ready else None

    def _receive(self, ref: ray.ObjectRef, i: int) -> Fragment | None:
        """The fragment of actor i, or None if it was lost; then the actor is asked again at
        once (a dead one waits at Ray until its restarted process takes the call). Reasons:
        `actor_died` (its process died: Ray restarts it), `object_lost` (the fragment was lost
        after it was made, e.g. with its node), `sampler` (the sampler did not answer the
        actor), `env_error` (an exception in the actor's env or policy)."""
        try:
            fragment = ray.get(ref, timeout=READY_TIMEOUT)  # ray.wait said it is ready
        except RayActorError:
            self._check_nodes(force=True)
            if i not in self.pool:
                return None  # lost with its node
            if i not in self.failing:
                self.restarts += 1
                self.failing.add(i)
            self._fragment_error(i, "actor_died", "its process died; Ray restarts it")
            return None
        except (ObjectLostError, GetTimeoutError) as e:
            self._fragment_error(i, "object_lost", type(e).__name__)
            return None
        except RayTaskError as e:
            cause = getattr(e, "cause", None)
            reason = "sampler" if isinstance(cause, SamplerUnavailable) else "env_error"
            self._fragment_error(i, reason, f"{type(cause).__name__}: {str(cause)[:200]}")
            return None
        except RayError as e:  # Ray failed the fragment: disk, memory, (de)serialization
            self._fragment_error(i, "ray_error", f"{type(e).__name__}: {_first_line(e)}")
            return None
        self.failing.discard(i)
        self.errors_in_a_row = 0
        return fragment

    def _fragment_error(self, i: int, reason: str, detail: str) -> None:
        """Drop actor i's fragment under `reason`, ask it again; FragmentsFailing after
        actors.max_fragment_errors errors in a row."""
        self.dropped += 1
        self.errors_in_a_row += 1
        first = reason not in self.fragment_errors
        self.fragment_errors[reason] = self.fragment_errors.get(reason, 0) + 1
        if first or self.fragment_errors[reason] % 100 == 0:  # not one event per fragment
            self.events.append(
                ("fragment_error", f"fragment of actor {i} dropped ({reason}): {detail}; "
                 f"{self.fragment_errors[reason]} so far", {"reason": reason, "actor": i,
                 "count": self.fragment_errors[reason]})
            )  # fmt: skip
        limit = self.cfg.actors.max_fragment_errors
        if self.errors_in_a_row >= limit:
            raise FragmentsFailing(
                f"{self.errors_in_a_row} fragments in a row failed (last: {reason}: {detail}); "
                f"errors so far: {self.fragment_errors}"
            )
        time.sleep(RETRY_PAUSE)  # do not spin on an actor that keeps failing
        if i in self.pool:
            self._request(i)

    def _kill_hung(self, answered: set[int]) -> None:
        """Kill the actors whose fragment is older than actors.fragment_timeout (a hung step,
        a stopped process); Ray restarts them and they are asked again."""
        now, timeout = time.monotonic(), self.cfg.actors.fragment_timeout
        for ref in [r for r, t in self.sent.items() if now - t > timeout]:
            i = self._forget(ref)
            if i not in self.pool:
                continue
            ray.cancel(ref, force=False)
            ray.kill(self.pool.handle(i), no_restart=False)
            self.restarts += 1
            answered.add(i)
            self._fragment_error(i, "timeout", f"no fragment within {timeout:.0f} s: killed")

    def take_events(self) -> list[tuple[str, str, dict]]:
        """(kind, message, data) of the node losses and joins since the last call."""
        events, self.events = self.pool.take_events() + self.events, []
        return events

    def stats(self) -> dict:
        return {
            "actors": len(self.pool),
            "nodes": self.pool.nodes,
            "actor_restarts": self.restarts,
            "actors_lost": self.pool.lost,
            "dropped_fragments": self.dropped,
            "fragment_errors": sum(self.fragment_errors.values()),
        }

    def pids(self) -> list[int]:
        return self.pool.pids()

    def close(self) -> None:
        for ref in self.pending:
            ray.cancel(ref, force=False)
        self.pending.clear()
        self.sent.clear()
        self.pool.close()


def _first_line(e: Exception) -> str:
    return (str(e).strip().splitlines() or [""])[0][:200]
