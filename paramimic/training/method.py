"""One object per training method: which env it trains in, its curriculum, what the learner
keeps besides PPO and V̄, and what it adds to an iteration.

- `WL19` — [WL19]: ParamEnv under the locomotion task (a procedural gait, or a looping clip as
  the reference gait, `env.gait`), the adaptive curriculum on V̄ (Alg. 1).
- `L21` — [L21]: SkillEnv on a clip (`env.clip`), the exploration/refinement curriculum with an
  elite set, P_θ and the bootstrap stages (§5-6).

A config's method is the first registered one that `applies` to it (`method_for`); a new
method is one subclass and one `register` call (tests/test_method.py adds a toy one). Nothing
outside these classes branches on which method a run is.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from paramimic.config import ConfigError, EnvConfig, ExperimentConfig
from paramimic.curriculum.adaptive import AdaptiveCurriculum
from paramimic.curriculum.skill import SkillCurriculum
from paramimic.envs import env_for
from paramimic.task_space import TaskSpace
from paramimic.training.curriculum import Curriculum, MotionCurriculum

if TYPE_CHECKING:  # evaluation loads torch; the sampler actor imports this module without it
    from paramimic.evaluation import Motions


@dataclass(frozen=True)
class Spaces:
    """A method's spaces on its config, read once per process from one env."""

    obs_dim: int
    act_dim: int
    task_space: TaskSpace
    # [L21]: the motion trace's shape and a0, what the curriculum needs of the clip
    trace_shape: tuple[int, int] | None = None
    reference: np.ndarray | None = None

    def clip_setup(self) -> dict | None:
        """What the [L21] curriculum needs of the clip (sent to the sampler actor): None else."""
        if self.trace_shape is None:
            return None
        return {"trace_shape": self.trace_shape, "reference": np.asarray(self.reference).tolist()}


class Method(ABC):
    """A training method on one experiment config (a subclass says when it applies and which
    curriculum it keeps; the rest has defaults)."""

    name: ClassVar[str]
    # what `paramimic play` offers: "family" (bodies and goals change on the fly) or "skill"
    # (set the task, then perform m_a from a reset)
    play_kind: ClassVar[str] = "family"

    def __init__(self, cfg: ExperimentConfig) -> None:
        self.cfg = cfg

    @classmethod
    @abstractmethod
    def applies(cls, cfg: ExperimentConfig) -> bool:
        """Whether this method trains `cfg`."""

    @classmethod
    def problems(cls, cfg: ExperimentConfig) -> list[str]:
        """What in `cfg` this method cannot run, each as 'field: reason' (the config's own
        validation has passed: these are the rules of the method, not of the data)."""
        return []

    def make_env(self, env: EnvConfig | None = None):
        """The method's env on this config (or on `env`, e.g. `cfg.env.for_evaluation()`)."""
        return env_for(self.cfg, env)

    @cached_property
    def spaces(self) -> Spaces:
        env = self.make_env()
        return Spaces(env.observation_space.shape[0], env.action_space.shape[0], env.task_space)

    @abstractmethod
    def new_curriculum(self, clip: dict | None = None) -> Curriculum:
        """The curriculum a run of this method keeps (in the sampler actor, or in-process).
        `clip`: `Spaces.clip_setup()` when the caller must not build an env (the sampler)."""

    def learner_parts(self, seed: int) -> dict[str, Any]:
        """What the learner keeps besides PPO and V̄: name -> an object with `to_state` and
        `from_state`, checkpointed under that name."""
        return {}

    def after_update(self, trainer, metrics: dict) -> dict:
        """Work of this method after each PPO/V̄ update (`trainer`: the Trainer); returns
        metrics to add to the iteration's."""
        return {}

    def performer(self, state: dict) -> Motions | None:
        """How a trained run of this method performs a task (evaluation, play): tasks [n, d] ->
        the motions to reset with (None: the env's own reference). `state`: a checkpoint's."""
        return None


class WL19(Method):
    name = "wl19"

    @classmethod
    def applies(cls, cfg: ExperimentConfig) -> bool:
        return cfg.env.clip is None

    @classmethod
    def problems(cls, cfg: ExperimentConfig) -> list[str]:
        from paramimic.characters import registration

        out = []
        measures = set(cfg.env.skill.measures)
        for name in sorted(({"gravity", "jump_height"} | measures) & set(cfg.task)):
            out.append(f"task.{name}: needs env.clip (the skill env); [WL19] gaits have no {name}")
        if cfg.env.gait is None and registration(cfg.character).gait is None:
            clips = sorted(registration(cfg.character).clips)
            out.append(
                f"character: {cfg.character!r} has no procedural [WL19] gait; set env.gait "
                f"(a looping clip) or env.clip (one of {clips})"
            )
        if cfg.env.deviation_limit is not None and cfg.env.gait is None:
            out.append(
                "env.deviation_limit: ends episodes that leave their reference: a clip gait's "
                "(env.gait) or a skill's (env.clip)"
            )
        return out

    def new_curriculum(self, clip: dict | None = None) -> Curriculum:
        return AdaptiveCurriculum.from_config(self.cfg)


class L21(Method):
    name = "l21"
    play_kind = "skill"

    @classmethod
    def applies(cls, cfg: ExperimentConfig) -> bool:
        return cfg.env.clip is not None

    @classmethod
    def problems(cls, cfg: ExperimentConfig) -> list[str]:
        out = []
        if cfg.curriculum.widen is not None:
            out.append(
                "curriculum.widen: a widening range is for [WL19] families (env.clip unset); "
                "[L21] skills grow their explored region by the exploration curriculum"
            )
        if cfg.env.retarget:
            out.append(
                "env.retarget: retargets the character's [WL19] gait (env.clip unset); [L21] "
                "skills adapt their clip by the motion displacement of P_θ"
            )
        if "target_velocity" in cfg.task:
            out.append("task.target_velocity: a [WL19] gait goal; the skill env has none")
        if cfg.env.phase_sampling == "failures" and cfg.env.skill.rsi == 0:
            out.append(
                "env.phase_sampling: failures draws the start phases of RSI episodes; set "
                "env.skill.rsi > 0"
            )
        return out

    @cached_property
    def spaces(self) -> Spaces:
        env = self.make_env()
        return Spaces(
            env.observation_space.shape[0], env.action_space.shape[0], env.task_space,
            env.trace_shape, env.reference_task(),
        )  # fmt: skip

    def new_curriculum(self, clip: dict | None = None) -> Curriculum:
        clip = clip if clip is not None else self.spaces.clip_setup()
        return SkillCurriculum.from_config(self.cfg, tuple(clip["trace_shape"]), clip["reference"])

    def learner_parts(self, seed: int) -> dict[str, Any]:
        """[L21] §5.2-5.3: the parameterization P_θ and the bootstrap stages."""
        # here, not at the top: the sampler actor builds curricula and need not load torch
        from paramimic.curriculum.bootstrap import Bootstrap
        from paramimic.curriculum.parameterization_net import ParameterizationNet

        sc, spaces = self.cfg.curriculum.skill, self.spaces
        return {
            "motion_net": ParameterizationNet(
                spaces.task_space, spaces.trace_shape, sc.p_hidden, sc.p_lr, sc.p_batch,
                seed=seed + 4,
            ),
            "bootstrap": Bootstrap(sc),
        }  # fmt: skip

    def performer(self, state: dict) -> Motions | None:
        """m_a = P_θ(a) of the checkpoint's curriculum (the kNN proxy, or m0, before it has
        one): `SkillCurriculum.performed_motions`."""
        curriculum: MotionCurriculum = self.new_curriculum()  # type: ignore[assignment]
        curriculum.from_state(state["curriculum"])
        return curriculum.performed_motions

    def after_update(self, trainer, metrics: dict) -> dict:
        """Fit P_θ on the elites every `p_every` updates, advance the bootstrap stage, and send
        both to the curriculum (which deals m_a with the tasks)."""
        sc, it = self.cfg.curriculum.skill, trainer.progress.iteration
        net, boot = trainer.parts["motion_net"], trainer.parts["bootstrap"]
        curriculum: MotionCurriculum = trainer.curriculum
        fitted = False
        if sc.motion_parameterization and it % sc.p_every == 0:
            params, traces = curriculum.elite_data()
            if len(params) >= 2:
                net.fit(params, traces, sc.p_steps)
                fitted = True
        before = boot.stage
        stage = boot.observe(it, metrics.get("mean_return"), net.mse)
        if fitted or stage != before:
            layers = net.layers() if net.loss is not None else None
            curriculum.update_motion(layers, net.version, net.mse, stage)
        return {"stage": stage, "motion_version": net.version, "motion_loss": net.mse}


METHODS: list[type[Method]] = [L21, WL19]


def register(method: type[Method]) -> type[Method]:
    """Add a method (it is asked first whether it `applies`); usable as a class decorator."""
    if method not in METHODS:
        METHODS.insert(0, method)
    return method


def method_for(cfg: ExperimentConfig) -> Method:
    """The method that trains `cfg`; ConfigError naming the field when the config asks for
    what that method cannot do (checked before anything starts: the train preflight, play)."""
    for method in METHODS:
        if method.applies(cfg):
            problems = method.problems(cfg)
            if problems:
                raise ConfigError(f"{cfg.name}: " + "; ".join(problems))
            return method(cfg)
    raise ConfigError(f"{cfg.name}: no training method applies to this config")
