"""The family environments and their gymnasium registrations: `paramimic/<Name>-v0` for every
registered character (its [WL19] gait, or its first [L21] clip), one env per clip
(`paramimic/WalkerPlanarJump-v0`, `paramimic/HumanoidBackflip-v0`, ...) and the extra task
spaces a registration names (`paramimic/WalkerLegs-v0`, ...)."""

from collections.abc import Mapping

import gymnasium as gym

from paramimic import characters
from paramimic.config import EnvConfig, ExperimentConfig
from paramimic.envs.param_env import REWARD_TERMS, ParamEnv
from paramimic.envs.skill_env import SkillEnv


def make_env(
    character: str,
    task: Mapping | None = None,
    config: EnvConfig | Mapping | None = None,
) -> ParamEnv | SkillEnv:
    """The environment of an experiment: the continuous-time SkillEnv ([L21]) when `env.clip`
    names a clip, else ParamEnv ([WL19] gaits)."""
    cfg = config if isinstance(config, EnvConfig) else EnvConfig.model_validate(config or {})
    env = SkillEnv if cfg.clip else ParamEnv
    return env(character=character, task=task, config=cfg)


def env_for(experiment: ExperimentConfig, env: EnvConfig | None = None) -> ParamEnv | SkillEnv:
    """An experiment's env: its character, task space and env section (or `env`, e.g.
    `experiment.env.for_evaluation()`)."""
    return make_env(experiment.character, experiment.task, experiment.env if env is None else env)


def registered_envs() -> dict[str, dict]:
    """Gymnasium id -> kwargs of every registered character's envs."""
    return {k: v for r in characters.REGISTRY.values() for k, v in r.env_specs().items()}


def register_envs() -> None:
    """Register the gymnasium envs of every character in the registry (idempotent)."""
    for env_id, kwargs in registered_envs().items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point="paramimic.envs:make_env", kwargs=kwargs)


def register(registration: characters.Registration) -> characters.Registration:
    """Add a character at run time: to the registry, and its envs to gymnasium."""
    characters.register(registration)
    register_envs()
    return registration


register_envs()

__all__ = [
    "REWARD_TERMS",
    "ParamEnv",
    "SkillEnv",
    "env_for",
    "make_env",
    "register",
    "register_envs",
    "registered_envs",
]
