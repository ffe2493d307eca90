"""Recipes: the papers' settings and ours as presets beneath a config, each field's source."""

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
import yaml

from paramimic.config import ConfigError, ExperimentConfig, load_config
from paramimic.envs import make_env
from paramimic.recipes import PRESETS, overrides


def test_the_papers_settings_as_the_papers_state_them():
    # [WL19] Table 2: 600 Hz, 30 Hz, α_π 5e-5, α_V 1e-4, T 4096, n 128, N 10, 30 s, γ = λ = 0.95
    wl19 = ExperimentConfig.model_validate({"character": "walker", "recipe": "wl19"})
    assert (wl19.env.physics_hz, wl19.env.control_hz, wl19.env.max_episode_seconds) == (
        600, 30, 30.0
    )  # fmt: skip
    p = wl19.ppo
    assert (p.policy_lr, p.value_lr, p.num_steps, p.minibatch_size, p.num_epochs) == (
        5e-5, 1e-4, 4096, 128, 10
    )  # fmt: skip
    assert (p.gamma, p.gae_lambda, p.learn_std, p.hidden_sizes) == (0.95, 0.95, True, (128,) * 3)
    assert wl19.curriculum.k == 10.0 and wl19.curriculum.p_mcmc == 20
    assert not wl19.env.retarget and wl19.env.stall_speed_ratio is None
    # [L21] §7: 150 Hz, a 4 x 1024 policy and a 2 x 512 value, minibatch 1024, k_p 600 / k_d 49
    l21 = ExperimentConfig.model_validate(
        {"character": "humanoid", "recipe": "l21", "env": {"clip": "humanoid_jump"}}
    )
    assert l21.env.physics_hz == 150 and l21.env.pd_gain == 600.0
    assert l21.ppo.hidden_sizes == (1024,) * 4 and l21.ppo.value_hidden_sizes == (512, 512)
    assert (l21.ppo.policy_lr, l21.ppo.value_lr, l21.ppo.minibatch_size) == (2e-4, 1e-3, 1024)
    assert l21.curriculum.p_mcmc == 5 and l21.env.skill.rsi == 0.0
    assert wl19.env.stable_pd and l21.env.stable_pd  # [WL19] Eq. 3; [L21] §7's stable PD
    # [WL19] §4.1: the root joint's frame; Eq. 6: d′ is the target direction. Both are also the
    # library defaults, so the preset itself must hold them, or a default changed later would
    # silently change the paper's recipe
    assert wl19.env.reward.end_effector_frame == "root" and wl19.env.reward.facing == "target"
    held = {k: s.value for k, s in PRESETS["wl19"].items() if k.startswith("env.reward.")}
    assert held["env.reward.end_effector_frame"] == "root"
    assert held["env.reward.facing"] == "target"
    assert not ExperimentConfig.model_validate({"character": "walker"}).env.stable_pd


def test_a_field_the_config_sets_wins_over_its_recipe_and_the_rest_is_the_default():
    cfg = ExperimentConfig.model_validate(
        {"character": "walker", "recipe": "wl19", "env": {"physics_hz": 300},
         "ppo": {"minibatch_size": 256}}
    )  # fmt: skip
    assert cfg.env.physics_hz == 300 and cfg.env.frame_skip == 10
    assert cfg.ppo.minibatch_size == 256 and cfg.ppo.value_lr == 1e-4  # the rest from wl19
    assert cfg.ppo.vf_coef == 0.5  # in no preset: the library default
    # the humanoid configs name their recipe instead of repeating it
    walk = load_config("configs/humanoid_walk.yaml")
    assert walk.recipe == "paramimic_humanoid"
    assert (walk.ppo.hidden_sizes, walk.ppo.num_steps, walk.actors.mode) == (
        (512, 256), 8192, "pipelined"
    )  # fmt: skip
    for name, settings in PRESETS.items():  # every preset validates on a character
        character = "walker" if name != "paramimic_humanoid" else "humanoid"
        cfg = ExperimentConfig.model_validate({"character": character, "recipe": name})
        assert cfg.recipe == name and settings


def test_a_recipe_as_overrides_wins_even_over_what_the_config_sets():
    # "at the paper's settings": walker_jump.yaml sets its own 300 Hz and minibatch; the
    # recipe as overrides puts [L21] §7's back, and names the recipe
    shipped = load_config("configs/walker_jump.yaml")
    assert shipped.env.physics_hz != 150
    paper = load_config("configs/walker_jump.yaml", overrides("l21"))
    assert paper.recipe == "l21" and paper.env.physics_hz == 150
    assert paper.ppo.hidden_sizes == (1024,) * 4 and paper.ppo.minibatch_size == 1024
    assert paper.curriculum.skill.sampling == shipped.curriculum.skill.sampling  # not in l21
    with pytest.raises(ValueError, match="recipe: unknown 'dl18'"):
        overrides("dl18")


def test_an_unknown_recipe_is_refused_naming_the_field(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({"character": "walker", "recipe": "deepmimic"}))
    with pytest.raises(ConfigError, match="recipe"):
        load_config(path)


def test_one_pd_gain_for_every_joint_with_the_papers_damping():
    env = make_env("humanoid", None, {"gait": "humanoid_walk", "pd_gain": 600.0})
    env.reset(seed=0)
    assert np.all(env.model.actuator_gainprm[:, 0] == 600.0)
    assert np.allclose(env.model.actuator_biasprm[:, 2], -49.0, atol=0.02)  # k_d 49 ([L21] §7)
    own = make_env("humanoid", None, {"gait": "humanoid_walk"})
    own.reset(seed=0)
    assert len(set(own.model.actuator_gainprm[:, 0])) > 1  # DeepMimic's gains, per joint


def test_a_value_network_of_its_own_size_acts_as_the_actors_compute_it():
    from paramimic.config import PPOConfig
    from paramimic.rl.ppo import PPOLearner

    cfg = PPOConfig(num_steps=256, minibatch_size=64, hidden_sizes=(32, 32, 32),
                    value_hidden_sizes=(16,))  # fmt: skip
    learner = PPOLearner(5, 2, cfg)
    shapes = [tuple(p.shape) for p in learner.policy.v.parameters()]
    assert shapes == [(16, 5), (16,), (1, 16), (1,)]
    assert len(list(learner.policy.pi.parameters())) == 8
    obs = np.random.default_rng(0).standard_normal((7, 5)).astype(np.float32)
    _, _, v_numpy = learner.policy.numpy_policy().act(obs, None)
    assert np.allclose(v_numpy, learner.policy.value(obs), atol=1e-5)
    with torch.no_grad():
        assert learner.policy(torch.from_numpy(obs))[1].shape == (7,)


def test_config_show_says_where_every_field_comes_from(tmp_path):
    path = tmp_path / "legs.yaml"
    path.write_text(yaml.safe_dump({"character": "walker", "recipe": "wl19",
                                    "ppo": {"gamma": 0.99}}))  # fmt: skip
    out = subprocess.run(
        [sys.executable, "-m", "services.cli", "config", "show", path, "--set", "ppo.num_epochs=3"],
        capture_output=True, text=True, timeout=120, env={**os.environ, "COLUMNS": "240"},
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    rows = {line.split("│")[1].strip(): line for line in out.stdout.splitlines() if "│" in line}
    assert "config" in rows["ppo.gamma"] and "0.99" in rows["ppo.gamma"]
    assert "config" in rows["ppo.num_epochs"] and " 3 " in rows["ppo.num_epochs"]
    assert "recipe wl19: [WL19] Table 2 (α_V)" in rows["ppo.value_lr"]
    assert "default: value loss weight" in rows["ppo.vf_coef"]
    bad = subprocess.run(
        [sys.executable, "-m", "services.cli", "config", "show", path, "--set", "recipe=x"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert bad.returncode == 2 and "recipe" in bad.stdout


def test_stable_pd_adds_the_stiffness_times_the_time_step_to_the_damping():
    """[WL19] Eq. 3: −k_p(q + h q̇ − q̄) is k_p h more damping; the papers' recipes set it."""
    plain = make_env("humanoid", None, {"gait": "humanoid_walk", "physics_hz": 150})
    stable = make_env("humanoid", None, {"gait": "humanoid_walk", "physics_hz": 150,
                                         "stable_pd": True})  # fmt: skip
    for env in (plain, stable):
        env.reset(seed=0)
    kp = plain.model.actuator_gainprm[:, 0]
    extra = plain.model.actuator_biasprm[:, 2] - stable.model.actuator_biasprm[:, 2]
    assert np.allclose(extra, kp / 150.0)  # e.g. the knee: k_p 500, h 1/150 s → 3.33 N·m·s/rad
    assert np.allclose(stable.model.actuator_gainprm[:, 0], kp)  # the stiffness itself unchanged
    shape = {"leg_length": (0.6, 0.6)}
    small = make_env("humanoid", shape, {"gait": "humanoid_walk", "physics_hz": 150,
                                         "stable_pd": True})  # fmt: skip
    small.reset(seed=0)  # a reshaped body is a stable-PD body too
    assert np.allclose(small.model.actuator_biasprm[:, 2] + kp / 150.0,
                       plain.model.actuator_biasprm[:, 2])  # fmt: skip
    l21 = make_env("humanoid", None, {"gait": "humanoid_walk", "physics_hz": 150,
                                      "pd_gain": 600.0, "stable_pd": True})  # fmt: skip
    l21.reset(seed=0)
    assert np.allclose(l21.model.actuator_biasprm[:, 2], -49.0 - 600.0 / 150.0, atol=0.02)
