"""The stepping loop: M environments stepped together with one batched policy forward per step.

The same code runs in the serial trainer and inside the Ray rollout actors. Task parameters come
from a `task_source(n)` (the curriculum's `TaskDeal`) whenever episodes start; each finished
episode yields an `EpisodeReport` (`paramimic.messages`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from paramimic.config import ActorsConfig, HorizonGrowthConfig
from paramimic.envs import ParamEnv
from paramimic.messages import DealTags, EpisodeReport, TaskDeal
from paramimic.rl.numpy_mlp import NumpyPolicy

# n -> the deal of the next n episodes (the curriculum's, or the sampler actor's)
TaskSource = Callable[[int], TaskDeal]


def as_deal(tasks: np.ndarray | TaskDeal) -> TaskDeal:
    return tasks if isinstance(tasks, TaskDeal) else TaskDeal(np.asarray(tasks, np.float64))


class TaskQueue:
    """A deal (or bare task parameters) handed out in order; it starts over if it runs out."""

    def __init__(self, tasks: np.ndarray | TaskDeal) -> None:
        self.deal = as_deal(tasks)
        self.next = 0

    def __call__(self, n: int) -> TaskDeal:
        idx = (self.next + np.arange(n)) % len(self.deal)
        self.next += n
        return self.deal.take(idx)


def horizon_of(cfg) -> tuple[HorizonGrowthConfig, int] | None:
    """A RolloutWorker's `horizon` for an experiment config (`cfg`: an ExperimentConfig)."""
    growth = cfg.env.horizon_growth
    return None if growth is None else (growth, cfg.ppo.num_steps)


def tasks_per_fragment(num_envs: int, num_steps: int) -> int:
    """Tasks to hand a worker for one fragment: its envs' next episodes, one per 10 steps each."""
    return num_envs * (1 + num_steps // 10)


def steps_per_fragment(actors: ActorsConfig, num_steps: int, num_workers: int) -> int:
    """Steps per env of one worker's fragment: `actors.steps_per_fragment`, or the batch T =
    `num_steps` split over the workers' envs (rounded up)."""
    envs = max(1, num_workers) * actors.num_envs
    return actors.steps_per_fragment or max(1, -(-num_steps // envs))


@dataclass
class Fragment:
    """T steps of M environments; every array is [T, M, ...]."""

    obs: np.ndarray  # [T, M, obs_dim] raw observations
    actions: np.ndarray  # [T, M, A]
    logp: np.ndarray  # [T, M]
    values: np.ndarray  # [T, M]
    next_values: np.ndarray  # [T, M] V of the true next state (final obs when truncated)
    rewards: np.ndarray  # [T, M] continuous rewards
    spike_rewards: np.ndarray  # [T, M]
    dphi: np.ndarray  # [T, M] reference time advanced per step
    terminated: np.ndarray  # [T, M] bool
    truncated: np.ndarray  # [T, M] bool
    task_index: np.ndarray  # [T, M] row of `tasks` in force at each step
    tasks: np.ndarray  # [K, d]
    episodes: list[EpisodeReport] = field(default_factory=list)
    policy_version: int = 0

    @property
    def num_steps(self) -> int:
        return int(self.rewards.size)


class RolloutWorker:
    """Holds M ParamEnvs and a policy copy; `collect(T)` returns a Fragment."""

    def __init__(
        self,
        make_env: Callable[[], ParamEnv],
        num_envs: int,
        obs_dim: int,
        act_dim: int,
        seed: int,
        worker_id: int = 0,
        task_source: TaskSource | None = None,
        id_prefix: str = "",
        horizon: tuple[HorizonGrowthConfig, int] | None = None,
    ) -> None:
        """`horizon`: env.horizon_growth and the env steps one policy version stands for
        (ppo.num_steps): each new version sets the envs' training time limit."""
        self.envs = [make_env() for _ in range(num_envs)]
        self.horizon = horizon
        self.obs_dim, self.act_dim = obs_dim, act_dim
        self.fast_policy: NumpyPolicy | None = None  # until the first weights arrive
        self.policy_version = -1
        self.rng = np.random.default_rng(seed)
        self.worker_id = worker_id
        self.id_prefix = id_prefix
        self.task_source = task_source
        self._episode_counter = 0
        self._seed = seed
        self._obs: np.ndarray | None = None
        self._ep: list[dict] = []

    def set_weights(self, weights: Mapping[str, np.ndarray], version: int) -> None:
        """The learner's policy (`ActorCritic.numpy_weights`; tensors work too) as `version`."""
        if version != self.policy_version:
            self.fast_policy = NumpyPolicy({k: np.asarray(v) for k, v in weights.items()})
            self.policy_version = version
            if self.horizon is not None:
                growth, samples_per_version = self.horizon
                for env in self.envs:
                    full = env.horizon_seconds
                    env.set_time_limit(growth.seconds(version * samples_per_version, full))

    def _tasks(self, n: int) -> TaskDeal | None:
        """The deal of the next n episodes (None: each env draws its own tasks)."""
        return None if self.task_source is None else as_deal(self.task_source(n))

    def _start(
        self, i: int, deal: TaskDeal | None, j: int = 0, seed: int | None = None
    ) -> np.ndarray:
        """Reset env i for row j of `deal`: its task and its motion m_a (if any)."""
        env = self.envs[i]
        options = None
        if deal is not None:
            options = {"task": deal.tasks[j]}
            if deal.motions is not None:
                options["motion"] = deal.motions[j]
        obs, info = env.reset(seed=seed, options=options)
        self._ep[i] = {
            "id": f"{self.id_prefix}w{self.worker_id}-s{self._seed}-e{self._episode_counter}",
            "task": info["task"],
            "ret": 0.0,
            "len": 0,
            "terms": {},
            "tags": DealTags() if deal is None else deal.tags(),
        }
        self._episode_counter += 1
        return obs

    def _reset_all(self) -> None:
        m = len(self.envs)
        self._ep = [{} for _ in range(m)]
        deal = self._tasks(m)
        seeds = self.rng.integers(0, 2**31 - 1, size=m)
        self._obs = np.stack([self._start(i, deal, i, int(seeds[i])) for i in range(m)])

    def collect(
        self, num_steps: int, tasks: np.ndarray | TaskDeal | None = None, use_policy: bool = True
    ) -> Fragment:
        """Step all envs `num_steps` times; episodes that start take `tasks` in order if given.

        `use_policy=False` steps with zero actions (the reference motion's PD targets) and no
        forward pass: the cost of the environments alone, for throughput measurements.
        """
        if tasks is not None:
            self.task_source = TaskQueue(tasks)
        if self._obs is None:
            self._reset_all()
        if use_policy and self.fast_policy is None:
            raise RuntimeError("set_weights before collecting with the policy")
        buf = _Buffers(num_steps, len(self.envs), self._obs.shape[1], self.act_dim)
        run = _Run(tasks=[ep["task"] for ep in self._ep], current=np.arange(len(self.envs)))
        obs = self._obs
        for t in range(num_steps):
            actions, logp, values = self._act(obs, use_policy)
            buf.record_act(t, obs, actions, logp, values, run.current)
            results = [env.step(a) for env, a in zip(self.envs, actions, strict=True)]
            buf.record_step(t, results)
            obs = self._finish_episodes(t, results, run)
        self._obs = obs
        return Fragment(
            **vars(buf),  # obs, actions, ..., task_index: the [T, M] arrays
            next_values=self._next_values(buf.values, obs, run.final_obs),
            tasks=np.stack(run.tasks),
            episodes=run.episodes,
            policy_version=self.policy_version,
        )

    def _act(self, obs: np.ndarray, use_policy: bool) -> tuple[np.ndarray, ...]:
        if not use_policy:
            m = len(obs)
            zeros = np.zeros(m, np.float32)
            return np.zeros((m, self.act_dim), np.float32), zeros, zeros
        noise = self.rng.standard_normal((len(obs), self.act_dim))
        return self.fast_policy.act(obs, noise)

    def _finish_episodes(self, t: int, results: list[tuple], run: _Run) -> np.ndarray:
        """Account each env's step to its episode; summarize the episodes that ended and start
        new ones in their envs. Returns the observations the policy sees next [M, obs_dim]."""
        ended = []
        for i, (obs, r, terminated, truncated, info) in enumerate(results):
            ep = self._ep[i]
            ep["ret"] += r
            ep["len"] += 1
            terms = ep["terms"]
            for k, v in info["reward_terms"].items():
                terms[k] = terms.get(k, 0.0) + v
            if terminated or truncated:
                if truncated:
                    run.final_obs.append((t, i, obs))  # bootstrapped from V(final obs)
                run.episodes.append(_summary(ep, info, bool(terminated)))
                ended.append(i)
        next_obs = np.stack([res[0] for res in results])
        if ended:
            deal = self._tasks(len(ended))
            for j, i in enumerate(ended):
                next_obs[i] = self._start(i, deal, j)
                run.tasks.append(self._ep[i]["task"])
                run.current[i] = len(run.tasks) - 1
        return next_obs

    def _next_values(
        self, values: np.ndarray, last_obs: np.ndarray, final_obs: list[tuple[int, int, np.ndarray]]
    ) -> np.ndarray:
        """V of each step's true next state [T, M]: the next step's value, V(last obs) after
        the fragment, and V(final obs) where an episode was truncated."""
        next_values = np.empty_like(values)
        next_values[:-1] = values[1:]
        if self.fast_policy is None:  # zero actions and values: nothing to bootstrap
            next_values[-1] = 0.0
            return next_values
        next_values[-1] = self.fast_policy.value(last_obs)
        if final_obs:
            vals = self.fast_policy.value(np.stack([o for _, _, o in final_obs]))
            for (t, i, _), v in zip(final_obs, vals, strict=True):
                next_values[t, i] = v
        return next_values


@dataclass
class _Run:
    """What a fragment accumulates besides its arrays."""

    tasks: list[np.ndarray]  # tasks in force: rows are added as episodes start
    current: np.ndarray  # [M] row of `tasks` of each env's episode
    final_obs: list[tuple[int, int, np.ndarray]] = field(default_factory=list)
    episodes: list[EpisodeReport] = field(default_factory=list)


class _Buffers:
    """The [T, M, ...] arrays of a fragment, filled step by step (named as Fragment's)."""

    def __init__(self, T: int, m: int, obs_dim: int, act_dim: int) -> None:
        self.obs = np.empty((T, m, obs_dim), np.float32)
        self.actions = np.empty((T, m, act_dim), np.float32)
        self.logp = np.empty((T, m), np.float32)
        self.values = np.empty((T, m), np.float32)
        self.rewards = np.empty((T, m), np.float32)
        self.spike_rewards = np.zeros((T, m), np.float32)
        self.dphi = np.ones((T, m), np.float32)
        self.terminated = np.zeros((T, m), bool)
        self.truncated = np.zeros((T, m), bool)
        self.task_index = np.empty((T, m), np.int32)

    def record_act(self, t, obs, actions, logp, values, current) -> None:
        self.obs[t], self.actions[t], self.logp[t], self.values[t] = obs, actions, logp, values
        self.task_index[t] = current

    def record_step(self, t: int, results: list[tuple]) -> None:
        _, r, terminated, truncated, infos = zip(*results, strict=True)
        spikes = [info["reward_spike"] for info in infos]
        self.spike_rewards[t] = spikes
        self.rewards[t] = np.subtract(r, spikes)  # continuous part of the reward
        self.dphi[t] = [info["dphi"] for info in infos]
        self.terminated[t] = terminated
        self.truncated[t] = truncated


def _summary(ep: dict, info: dict, terminated: bool) -> EpisodeReport:
    return EpisodeReport(
        episode_id=ep["id"],
        task=np.asarray(ep["task"]),
        ret=ep["ret"],
        length=ep["len"],
        fell=bool(info["fell"]),
        diverged=bool(info["diverged"]),
        reward_terms=ep["terms"],
        ended_early=terminated,
        deviated=bool(info.get("deviated", False)),
        skill=info.get("skill"),
        tags=ep["tags"],
    )
