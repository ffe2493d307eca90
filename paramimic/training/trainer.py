"""The training loop: collect fragments, update PPO and V̄, send V̄ to the curriculum, checkpoint.

[WL19] Alg. 1 with the rollouts behind a `RolloutBackend` and the task sampling behind a
`Curriculum`: in-process (`SerialBackend` and `AdaptiveCurriculum`, for `--serial`) or on Ray
(`services.learner.ray_backend.RayBackend` and the sampler actor through `SamplerClient`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from paramimic.config import ExperimentConfig
from paramimic.curriculum.marginal_value import MarginalValue
from paramimic.envs import env_for
from paramimic.evaluation import deterministic, run_episodes
from paramimic.messages import EpisodeReport
from paramimic.rl.ppo import PPOLearner, adopt_controller
from paramimic.rl.rollout import (
    Fragment,
    RolloutWorker,
    horizon_of,
    steps_per_fragment,
    tasks_per_fragment,
)
from paramimic.task_space import TaskSpace
from paramimic.training import checkpoint
from paramimic.training.curriculum import Curriculum, WideningCurriculum
from paramimic.training.method import Method, method_for
from paramimic.training.tracking import (
    TensorBoardLog,
    WandbLog,
    close_figure,
    marginal_figure,
)


class StopRequested(Exception):
    """A backend was asked to stop while it waited for fragments: the iteration is abandoned
    before anything changed, and `train` ends as if the stop came between iterations."""


class WriteRefused(RuntimeError):
    """This trainer may no longer write its run (`train`'s `may_write` said no: on Ray, its
    lease on the run is gone and another learner may own it)."""


class TrainingDiverged(RuntimeError):
    """Updates kept producing non-finite losses or gradients; the run stopped with a checkpoint."""


class RolloutBackend(Protocol):
    def collect(self, weights: dict[str, np.ndarray], version: int) -> list[Fragment]: ...

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
        curriculum: Curriculum,
    ) -> None:
        m = cfg.actors.num_envs
        self.steps = steps_per_fragment(cfg.actors, cfg.ppo.num_steps, num_workers=1)
        self.n_tasks = tasks_per_fragment(m, self.steps)
        self.curriculum = curriculum
        self.worker = RolloutWorker(
            lambda: env_for(cfg),
            m,
            obs_dim,
            act_dim,
            seed=cfg.train.seed + 1,
            worker_id=0,
            horizon=horizon_of(cfg),
        )

    def collect(self, weights: dict[str, np.ndarray], version: int) -> list[Fragment]:
        self.worker.set_weights(weights, version)
        fragment = self.worker.collect(self.steps, self.curriculum.next_deal(self.n_tasks))
        self.curriculum.ingest(fragment.episodes)
        return [fragment]

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
    """The learner. `curriculum` is the sampler actor's client when the rollouts run on Ray
    (then `train.torch_threads: auto` is one thread: the actors use the cores); without it the
    trainer runs its own curriculum and, with `--serial`, has the machine to itself."""

    def __init__(
        self,
        cfg: ExperimentConfig,
        run_dir: Path,
        curriculum: Curriculum | None = None,
        method: Method | None = None,
    ) -> None:
        self.cfg = cfg
        self.run_dir = Path(run_dir)
        self.method = method or method_for(cfg)
        spaces = self.method.spaces
        self.space: TaskSpace = spaces.task_space
        self.obs_dim, self.act_dim = spaces.obs_dim, spaces.act_dim
        # a serial trainer has the machine to itself; on Ray the actors use the cores
        threads = cfg.train.torch_threads
        if threads == "auto":
            threads = 1 if curriculum is not None else (os.cpu_count() or 1)
        torch.set_num_threads(threads)
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
        self.parts = self.method.learner_parts(seed)  # [L21]: P_θ and the bootstrap stages
        if cfg.train.init_from is not None:
            self.warm_start(checkpoint.load(cfg.train.init_from))
        self.curriculum = curriculum or self.method.new_curriculum()
        self.progress = Progress()
        self._consistent = True  # False while an update is changing the state
        self.bad_updates = 0  # updates in a row with skipped non-finite steps
        self.episode_ids: list[str] = []  # the episodes the last iteration learned from

    # --- state --------------------------------------------------------------------------------

    def state_dict(self) -> dict:
        return {
            "config": self.cfg.model_dump(mode="json"),
            "learner": self.learner.state_dict(),
            "marginal": self.marginal.to_state(),
            "curriculum": self.curriculum.to_state(),
            **{name: part.to_state() for name, part in self.parts.items()},
            "progress": vars(self.progress).copy(),
            "obs_dim": self.obs_dim,
            "act_dim": self.act_dim,
        }

    def load_state_dict(self, state: dict) -> None:
        self.learner.load_state_dict(state["learner"])
        self.marginal.from_state(state["marginal"])
        self.curriculum.from_state(state["curriculum"])
        for name, part in self.parts.items():
            part.from_state(state[name])
        self.progress = Progress(**state["progress"])

    def warm_start(self, state: dict) -> None:
        """Start π, V and the normalizer from another run's checkpoint or a shipped controller
        (`train.init_from`) of the same character, env and action layout, whose task space is
        this one's or a part of it in the same order (a family varying more shape parameters
        than its base controller observed): `adopt_controller`, with 64 resets of this config's
        env as the new inputs' statistics; optimizers, V̄ and the curriculum start fresh. A
        frozen std (`ppo.learn_std: false`) is this config's."""
        inserted = self._inserted_inputs(state)
        source = None  # a shipped controller keeps no normalizer: its own resets tell
        if "normalizer" not in state["learner"]:
            source = reset_observations(ExperimentConfig.model_validate(state["config"]))
        observations = reset_observations(self.cfg)
        adopt_controller(self.learner, state["learner"], observations, inserted, source)
        if not self.cfg.ppo.learn_std:
            with torch.no_grad():
                self.learner.policy.log_std.fill_(self.cfg.ppo.init_log_std)

    def _inserted_inputs(self, state: dict) -> np.ndarray:
        """The observation indices of this config's task dims the source did not observe."""
        mine = list(self.cfg.task)
        theirs = list(state["config"].get("task", {}))
        new = [i for i, name in enumerate(mine) if name not in theirs]
        fits = [n for n in mine if n in theirs] == theirs and state["act_dim"] == self.act_dim
        if not fits or state["obs_dim"] + len(new) != self.obs_dim:
            raise ValueError(
                f"train.init_from: {self.cfg.train.init_from} has observation/action sizes "
                f"{state['obs_dim']}/{state['act_dim']} and task {theirs}; this config's env has "
                f"{self.obs_dim}/{self.act_dim} and task {mine} (same character and env needed, "
                "the source's task dims in the same order)"
            )
        return np.asarray(new, dtype=int)  # the task opens the observation

    def save_checkpoint(self) -> Path:
        keep = self.cfg.train.keep_checkpoints
        return checkpoint.save(self.run_dir, self.state_dict(), self.progress.iteration, keep)

    # --- loop ---------------------------------------------------------------------------------

    def iteration(self, backend: RolloutBackend) -> dict:
        """One iteration of Alg. 1; returns its metrics."""
        cfg, it = self.cfg, self.progress.iteration
        t0 = time.perf_counter()
        if self.marginal.fitted:  # l.3: S is refilled every P_MCMC iterations
            refill = it % cfg.curriculum.p_mcmc == 0
            with self._mutating():
                self.curriculum.update_marginal(
                    self.marginal.layers(), self.marginal.mu, it, refill
                )
        fragments = backend.collect(self.learner.weights(), self.learner.version)
        t_collect = time.perf_counter() - t0
        with self._mutating():
            metrics = self._learn(fragments)
        elapsed = time.perf_counter() - t0
        steps = sum(f.num_steps for f in fragments)
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

    @contextmanager
    def _mutating(self):
        """Marks a span that changes the learner's state: an interrupt inside it (a second
        Ctrl-C) leaves a state that is not checkpointed (`train` keeps the last good file)."""
        self._consistent = False
        yield
        self._consistent = True

    def _learn(self, fragments: list) -> dict:
        """Alg. 1 l.21-26 on the collected fragments, and the run's counters."""
        cfg = self.cfg
        batch = self.learner.build_batch(fragments)
        metrics = self.learner.update(batch)  # l.21-23
        # l.24-26: as many minibatch steps on (a, v) pairs as PPO took on transitions
        gradient_steps = cfg.ppo.num_epochs * max(1, len(batch.obs) // cfg.ppo.minibatch_size)
        metrics["marginal_loss"] = self.marginal.fit(batch.tasks, batch.values, gradient_steps)
        episodes = [e for f in fragments for e in f.episodes]
        self.episode_ids = [e.episode_id for e in episodes]  # the run's reporter records them
        steps = sum(f.num_steps for f in fragments)
        self.progress.iteration += 1
        self.progress.env_steps += steps
        self.progress.episodes += len(episodes)
        metrics.update(episode_metrics(episodes))
        metrics.update(self.method.after_update(self, metrics))
        if cfg.curriculum.widen is not None:  # how much of the task range is in use
            metrics.update(self.check_edge())
            metrics["range_width"] = self.curriculum.summary().range_width
        self.bad_updates = self.bad_updates + 1 if metrics["skipped_steps"] else 0
        return metrics

    def check_edge(self) -> dict:
        """`curriculum.widen.promote_on: edge`: every `check_every` iterations, the policy's
        mean action on `window` bodies at the range's edge, episodes of the evaluation's
        horizon; the curriculum widens the range when few fell. Its steps are not training
        samples (`edge_env_steps`: simulated besides env_steps)."""
        cfg, it = self.cfg, self.progress.iteration
        rule = cfg.curriculum.widen
        if rule.promote_on != "edge" or it % rule.check_every:
            return {}
        seed = cfg.train.seed * 7919 + it
        curriculum: WideningCurriculum = self.curriculum
        tasks = curriculum.edge_tasks(rule.window, seed)
        if tasks is None:  # the range is whole
            return {}
        env_cfg = cfg.env.for_evaluation(None)
        results = run_episodes(
            deterministic(self.learner.policy),
            lambda: env_for(cfg, env_cfg),
            tasks,
            cfg.actors.num_envs,
            seed,
        )
        falls = sum(r.fell for r in results)
        curriculum.judge_edge(len(results), falls)
        return {
            "edge_fall_percent": 100.0 * falls / len(results),
            "edge_env_steps": sum(r.length for r in results),
        }

    def _boards(self) -> list:
        """Where the curves go besides metrics.jsonl: TensorBoard, and W&B when asked for."""
        t = self.cfg.train
        boards: list = []
        if t.tensorboard:
            boards.append(TensorBoardLog(self.run_dir / "tensorboard", self.progress.env_steps))
        if t.wandb != "off":
            name = self.run_dir.name
            config = self.cfg.model_dump(mode="json", exclude={"env": {"clip_texts"}})
            boards.append(WandbLog(self.run_dir, name, t.wandb, t.wandb_project, config))
        return boards

    def _to_boards(self, boards: list, row: dict) -> None:
        """A metrics row, the curriculum's summary and, every checkpoint interval, the V̄ map."""
        if not boards:
            return
        summary, fig = self.curriculum.summary(), None
        if self.progress.iteration % self.cfg.train.checkpoint_every == 0:
            fig = marginal_figure(self.space, self.cfg.display_dims(), self.marginal.predict)
        for board in boards:
            board.log(row, summary, fig)
        close_figure(fig)

    def _metrics_log(self) -> MetricsLog:
        """metrics.jsonl to append to, without the rows of iterations this run's state never
        saw: a run stopped between checkpoints resumes from the last one, and the iterations
        after it, logged but lost, would otherwise stay in its curve twice."""
        path = self.run_dir / "metrics.jsonl"
        if path.exists():
            rows = path.read_text().splitlines(keepends=True)
            kept = [r for r in rows if r.strip() and _logged_steps(r) <= self.progress.env_steps]
            if len(kept) != len(rows):
                tmp = path.with_suffix(".tmp")
                tmp.write_text("".join(kept))
                tmp.replace(path)
        return MetricsLog(path)

    def train(
        self,
        backend: RolloutBackend,
        total_steps: int,
        on_metrics: Callable[[dict], None] | None = None,
        should_stop: Callable[[], bool] = lambda: False,
        before_iteration: Callable[[], None] | None = None,
        on_checkpoint: Callable[..., None] | None = None,
        may_write: Callable[[], bool] = lambda: True,
    ) -> None:
        """Iterate until `total_steps` env steps; checkpoint every K iterations and at the end.

        `before_iteration` may block (a paused run); `should_stop` is asked before and after it.
        `may_write` is asked before every metrics row and checkpoint: False stops the run
        (`WriteRefused`) without writing either, also on the way out.
        """
        refused = False

        def check_write() -> None:
            nonlocal refused
            if not may_write():
                refused = True
                raise WriteRefused(
                    f"iteration {self.progress.iteration}: this learner may no longer write the "
                    "run (its lease is gone); nothing more was written"
                )

        def checkpoint_now(final: bool = False) -> None:
            """A periodic checkpoint that cannot be written (a full disk) is reported and
            training goes on (the last written one stands); the final one raises."""
            check_write()
            try:
                path = self.save_checkpoint()
            except OSError as e:
                if final:
                    raise
                message = (
                    f"checkpoint at iteration {self.progress.iteration} not written ({e}); "
                    f"training goes on, the last checkpoint stands"
                )
                logging.getLogger(__name__).warning(message)
                if on_checkpoint:
                    on_checkpoint(None, self.progress.iteration, message)
                return
            if on_checkpoint:
                on_checkpoint(path, self.progress.iteration)

        self.run_dir.mkdir(parents=True, exist_ok=True)
        log = self._metrics_log()
        boards = self._boards()
        try:
            while self.progress.env_steps < total_steps and not should_stop():
                if before_iteration:
                    before_iteration()
                    if should_stop():
                        break
                try:
                    m = self.iteration(backend)
                except StopRequested:
                    break
                check_write()
                log.write(json.dumps(m) + "\n")
                self._to_boards(boards, m)
                if on_metrics:
                    on_metrics(m)
                if self.bad_updates >= self.cfg.train.max_bad_updates:
                    raise TrainingDiverged(
                        f"{self.bad_updates} updates in a row had non-finite losses or "
                        f"gradients (their steps were skipped, the weights are the last finite "
                        f"ones); stopping at iteration {self.progress.iteration}"
                    )
                if self.progress.iteration % self.cfg.train.checkpoint_every == 0:
                    checkpoint_now()
        finally:
            log.close()
            for board in boards:
                board.close()
            if refused:
                pass  # the run is no longer this learner's to write
            elif self._consistent:
                checkpoint_now(final=True)
            else:  # interrupted inside an update: the last checkpoint stands
                logging.getLogger(__name__).warning(
                    f"interrupted during an update at iteration {self.progress.iteration}: "
                    f"no checkpoint written, the last one stands"
                )


def train_serial(cfg: ExperimentConfig, steps: int, run_dir: Path | None = None) -> Trainer:
    """Train `cfg` in this process to `steps` env steps (`paramimic train --serial` without
    Redis or the API), continuing from the run directory's latest checkpoint when it has one;
    returns the trainer (its `learner.policy` is the controller)."""
    run_dir = Path(run_dir or cfg.resolved_run_dir())
    trainer = Trainer(cfg, run_dir)
    latest = checkpoint.checkpoint_dir(run_dir) / checkpoint.LATEST
    if latest.exists():
        trainer.load_state_dict(checkpoint.load(latest))
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    try:
        trainer.train(backend, steps)
    finally:
        backend.close()
    return trainer


class MetricsLog:
    """metrics.jsonl, appended a row per iteration. A row the disk has no room for is kept and
    written with the next one (the file cut back to its last whole row): a full disk costs no
    rows and does not end the run; it is warned about once per spell."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.pending: list[str] = []
        self.failing = False

    def write(self, row: str) -> None:
        self.pending.append(row)
        self.flush()

    def flush(self) -> None:
        if not self.pending:
            return
        size = self.path.stat().st_size if self.path.exists() else 0
        try:
            with self.path.open("a") as f:
                f.write("".join(self.pending))
        except OSError as e:
            with contextlib.suppress(OSError):  # no half row left behind
                os.truncate(self.path, size)
            if not self.failing:
                logging.getLogger(__name__).warning(
                    f"{self.path} not written ({e}); its rows are kept and written once it can be"
                )
            self.failing = True
            return
        self.pending.clear()
        self.failing = False

    def close(self) -> None:
        self.flush()


def _logged_steps(row: str) -> float:
    """The env steps of a metrics.jsonl row; a torn row (the process killed mid-write): inf."""
    try:
        return float(json.loads(row)["env_steps"])
    except (ValueError, KeyError, TypeError):
        return float("inf")


def reset_observations(cfg: ExperimentConfig, n: int = 64) -> np.ndarray:
    """Observations of `n` resets of the config's env (random tasks): [n, obs_dim]."""
    env = env_for(cfg)
    return np.stack([env.reset(seed=cfg.train.seed * 1000 + i)[0] for i in range(n)])


def episode_metrics(episodes: list[EpisodeReport]) -> dict:
    if not episodes:
        return {"episodes": 0}
    return {
        "episodes": len(episodes),
        "mean_return": float(np.mean([e.ret for e in episodes])),
        "mean_length": float(np.mean([e.length for e in episodes])),
        "fall_percent": 100.0 * float(np.mean([e.fell for e in episodes])),
        "diverged": int(sum(e.diverged for e in episodes)),
        "deviated_percent": 100.0 * float(np.mean([e.deviated for e in episodes])),
    }
