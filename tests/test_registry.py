"""The character registry: a new character is one definition plus one registration, and then it
is a gymnasium env, a valid config and a trainable family."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from paramimic.characters import REGISTRY, Character, Registration, registration
from paramimic.characters.body import CharacterDef, Joint, Segment, ShapeParam
from paramimic.config import ExperimentConfig
from paramimic.envs import register, registered_envs
from paramimic.motion.procedural import gait
from paramimic.training.trainer import SerialBackend, Trainer

# --- a toy character, as a user would add one: a torso on one stiff-kneed leg ---------------


def _toy_scales(shape):
    leg = shape["leg_scale"]
    return {"torso": (1.0, 1.0), "leg": (leg, 1.0), "sole": (1.0, 1.0)}


TOY = CharacterDef(
    name="toy_pogo",
    segments=(
        Segment("torso", None, 0.3, 0.05, direction=(0.0, 0.0, 1.0)),
        Segment("leg", "torso", 0.5, 0.04, Joint("hip", (-1.0, 1.0), 100.0, 80.0), attach="start"),
        Segment("sole", "leg", 0.2, 0.05, Joint("ankle", (-0.5, 0.5), 40.0, 30.0), kind="foot"),
    ),
    shape_params=(ShapeParam("leg_scale", 0.8, 1.2, "leg length"),),
    scales=_toy_scales,
    legs=(("leg",),),
    end_effectors=("sole", "torso"),
    feet=("sole",),
)
TOY_GAIT = gait(("hip", "ankle"), 0.8, {"hip": (0.0, 0.2, 0.0, 0.0)})
TOY_REGISTRATION = Registration(TOY, gait=TOY_GAIT)


def test_every_character_is_registered_with_a_gymnasium_env():
    assert {"walker", "hopper", "humanoid", "biped_lower", "quadruped", "fish", "manta"} <= set(
        REGISTRY
    )
    for name, reg in REGISTRY.items():
        assert isinstance(reg.character, Character)
        assert f"paramimic/{reg.title}-v0" in gym.registry, name
    for env_id in ("paramimic/Quadruped-v0", "paramimic/BipedLower-v0", "paramimic/Manta-v0"):
        env = gym.make(env_id)
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        env.close()
    # the skill envs: one per clip
    assert {"paramimic/WalkerPlanarJump-v0", "paramimic/HumanoidBackflip-v0"} <= set(gym.registry)


def test_a_new_character_is_one_definition_and_one_registration(tmp_path):
    register(TOY_REGISTRATION)  # the one line
    assert registration("toy_pogo") is TOY_REGISTRATION
    assert "paramimic/ToyPogo-v0" in gym.registry
    assert "paramimic/ToyPogo-v0" in registered_envs()
    env = gym.make("paramimic/ToyPogo-v0")
    check_env(env.unwrapped)
    env.close()

    cfg = ExperimentConfig.model_validate(
        {
            "name": "toy",
            "character": "toy_pogo",
            "task": {"leg_scale": [0.8, 1.2], "target_velocity": [0.5, 0.5]},
            "env": {"max_episode_seconds": 2.0},
            "ppo": {"num_steps": 128, "minibatch_size": 64, "num_epochs": 1},
            "actors": {"num_envs": 2},
            "train": {"total_steps": 128},
        }
    )
    trainer = Trainer(cfg, tmp_path)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    metrics = trainer.iteration(backend)
    assert metrics["iteration"] == 1 and metrics["env_steps"] == 128
    assert np.isfinite(metrics["policy_loss"])


def test_registering_twice_or_a_wrong_gait_is_refused():
    register(TOY_REGISTRATION)  # the same registration again: nothing changes
    with pytest.raises(ValueError, match="already registered"):
        register(Registration(TOY, gait=TOY_GAIT))
    wrong = CharacterDef(**{**TOY.__dict__, "name": "toy_wrong"})
    with pytest.raises(ValueError, match="gait joints"):
        register(Registration(wrong, gait=gait(("ankle", "hip"), 1.0, {})))
    with pytest.raises(ValueError, match="unknown character 'toy_missing'.*known"):
        ExperimentConfig.model_validate({"character": "toy_missing"})


def test_a_serial_trainer_updates_on_every_core(tmp_path):
    import os

    import torch

    cfg = ExperimentConfig.model_validate(
        {"character": "hopper", "task": {"leg_length": [0.8, 1.2]}}
    )
    assert cfg.train.torch_threads == "auto"
    Trainer(cfg, tmp_path)
    assert torch.get_num_threads() == (os.cpu_count() or 1)
    Trainer(cfg.model_copy(update={"train": cfg.train.model_copy(update={"torch_threads": 1})}),
            tmp_path)  # fmt: skip
    assert torch.get_num_threads() == 1


def test_import_paramimic_registers_the_gym_envs_cheaply():
    """`import paramimic` is enough for gym.make (as gymnasium plugins do), without
    MuJoCo, torch, Ray or Redis; its id table equals the registry's."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    table = Path(__file__).resolve().parent.parent / "paramimic" / "gym_envs.json"
    fresh = subprocess.run(  # the built-in registry, without characters tests add
        [sys.executable, "-c", "import json; from paramimic.envs import registered_envs;"
         "print(json.dumps(registered_envs()))"], capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    assert json.loads(table.read_text()) == json.loads(fresh), (
        "paramimic/gym_envs.json is stale: python -m paramimic.envs"
    )
    code = (
        "import sys, paramimic, gymnasium as gym;"
        "heavy = [m for m in ('mujoco', 'torch', 'ray', 'redis') if m in sys.modules];"
        "assert not heavy, heavy;"
        "env = gym.make('paramimic/WalkerLegs-v0'); print(env.reset(seed=0)[0].shape)"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
