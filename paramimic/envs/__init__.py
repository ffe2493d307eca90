"""ParamEnv and its gymnasium registrations (`paramimic/WalkerLegs-v0`, ...)."""

import gymnasium as gym

from paramimic.envs.param_env import REWARD_TERMS, ParamEnv
from paramimic.envs.skill_env import SkillEnv

_ENTRY = "paramimic.envs.param_env:ParamEnv"
_LEGS = (0.7, 1.3)

# name -> (character, task space)
REGISTERED = {
    "paramimic/Walker-v0": ("walker", {"target_velocity": (1.0, 1.0)}),
    "paramimic/WalkerLegs-v0": (
        "walker",
        {"left_leg_length": _LEGS, "right_leg_length": _LEGS, "target_velocity": (1.0, 1.0)},
    ),
    "paramimic/Hopper-v0": ("hopper", {"target_velocity": (1.0, 1.0)}),
    "paramimic/HopperShape-v0": (
        "hopper",
        {"leg_length": _LEGS, "torso_length": (0.8, 1.2), "target_velocity": (1.0, 1.0)},
    ),
}


def register_envs() -> None:
    for env_id, (character, task) in REGISTERED.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=_ENTRY, kwargs={"character": character, "task": task})


register_envs()


def make_env(character: str, task: dict, env_config) -> ParamEnv | SkillEnv:
    """The environment of an experiment: the continuous-time SkillEnv ([L21]) when `env.clip`
    names a clip, else ParamEnv ([WL19] gaits)."""
    if getattr(env_config, "clip", None):
        return SkillEnv(character=character, task=task, config=env_config)
    return ParamEnv(character=character, task=task, config=env_config)


__all__ = ["REGISTERED", "REWARD_TERMS", "ParamEnv", "SkillEnv", "make_env", "register_envs"]
