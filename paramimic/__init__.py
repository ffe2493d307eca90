"""paramimic: parametric physics-based character controllers ([WL19], [L21]).

`import paramimic` registers the gymnasium ids of the built-in characters' envs
(`gym.make("paramimic/WalkerLegs-v0")`), as gymnasium plugin packages do, without importing
MuJoCo, torch, Ray or Redis: the ids come from `gym_envs.json` (written from the character
registry, `python -m paramimic.envs`; a test keeps them equal) and gymnasium imports
`paramimic.envs` only when an env is made."""

import json
from pathlib import Path

__version__ = "0.1.0"


def _register_gym_envs() -> None:
    import gymnasium as gym

    specs = json.loads((Path(__file__).parent / "gym_envs.json").read_text())
    for env_id, kwargs in specs.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point="paramimic.envs:make_env", kwargs=kwargs)


_register_gym_envs()
