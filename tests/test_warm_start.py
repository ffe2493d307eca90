"""A family trained from its base body's controller (`train.init_from`)."""

import math

import numpy as np
import pytest
import torch

from paramimic.config import ExperimentConfig
from paramimic.envs import env_for, make_env
from paramimic.training.preflight import PreflightError, preflight
from paramimic.training.trainer import SerialBackend, Trainer


def _config(tmp_path, name: str, legs: tuple[float, float], **train) -> ExperimentConfig:
    return ExperimentConfig.model_validate(
        {
            "character": "walker",
            "task": {"left_leg_length": legs, "right_leg_length": legs, "target_velocity": [1, 1]},
            "env": {"physics_hz": 300},
            "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 1, "hidden_sizes": [32],
                    "learn_std": False, "init_log_std": math.log(0.2)},
            "curriculum": {"k": 0.0},
            "actors": {"num_envs": 4},
            "train": {"run_dir": str(tmp_path / name), "torch_threads": 1, **train},
        }
    )  # fmt: skip


@pytest.fixture
def base_run(tmp_path):
    """Two iterations of the base body alone (legs fixed at 1.0), checkpointed."""
    cfg = _config(tmp_path, "base", (1.0, 1.0))
    (tmp_path / "base").mkdir()
    trainer = Trainer(cfg, tmp_path / "base")
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    trainer.train(backend, 512)
    backend.close()
    return trainer


def test_the_family_starts_acting_as_the_base_controller_on_every_body(tmp_path, base_run):
    cfg = _config(tmp_path, "family", (0.7, 1.3), init_from=str(tmp_path / "base"))
    family = Trainer(cfg, tmp_path / "family")
    env = make_env("walker", cfg.task, cfg.env)
    legs = {"left_leg_length": 1.0, "right_leg_length": 1.0, "target_velocity": 1.0}
    obs = np.stack([env.reset(seed=i, options={"task": legs})[0] for i in range(8)])
    # inputs constant for the base body that vary in the family: the legs, and what follows
    # from them (the body's target speed); the target velocity stays fixed in both
    constant = np.flatnonzero(
        (base_run.learner.normalizer.var < 1e-10) & (family.learner.normalizer.var > 1e-10)
    )
    assert {0, 1} <= set(constant) and 2 not in constant
    with torch.no_grad():
        base_mean, base_value = base_run.learner.policy(torch.from_numpy(obs))
        other = obs.copy()
        other[:, constant] += 0.2  # another body: what was constant is ignored at first
        for o in (obs, other):
            mean, value = family.learner.policy(torch.from_numpy(o))
            torch.testing.assert_close(mean, base_mean)
            torch.testing.assert_close(value, base_value)
    # the leg inputs are scaled as the uniform distribution over [0.7, 1.3] is (from 64
    # resets), and so is what follows from the legs, e.g. the body's target speed
    np.testing.assert_allclose(family.learner.normalizer.mean[:2], 1.0, atol=0.06)
    np.testing.assert_allclose(family.learner.normalizer.var[:2], 0.6**2 / 12, rtol=0.4)
    assert family.learner.normalizer.var[constant].min() > 1e-6  # none of them is a constant
    # and the family learns to use them: the leg columns move with training
    backend = SerialBackend(cfg, family.obs_dim, family.act_dim, family.curriculum)
    family.train(backend, 512)
    backend.close()
    assert float(family.learner.policy.pi[0].weight[:, :2].detach().abs().sum()) > 0
    assert family.learner.policy.log_std.exp().mean().item() == pytest.approx(0.2)


def test_a_checkpoint_of_another_layout_is_refused_naming_the_field(tmp_path, base_run):
    cfg = ExperimentConfig.model_validate(
        {
            "character": "walker",
            "task": {"target_velocity": [1, 1]},
            "ppo": {"hidden_sizes": [32]},
            "train": {"init_from": str(tmp_path / "base"), "run_dir": str(tmp_path / "x")},
        }
    )
    with pytest.raises(ValueError, match="train.init_from"):
        Trainer(cfg, tmp_path / "x")


def test_a_widening_family_reports_its_width_each_iteration(tmp_path):
    raw = _config(tmp_path, "wide", (0.7, 1.3)).model_dump()
    raw["curriculum"]["widen"] = {"start": 0.3, "window": 4}
    cfg = ExperimentConfig.model_validate(raw)
    trainer = Trainer(cfg, tmp_path / "wide")
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    m = trainer.iteration(backend)
    backend.close()
    assert 0.3 <= m["range_width"] <= 1.0
    width = trainer.curriculum.width
    legs = trainer.curriculum.next_tasks(100)[:, :2]  # 1 ± 0.3 of the whole range, scaled
    assert np.all(np.abs(legs - 1.0) <= 0.3 * width + 1e-9)


def test_an_edge_judged_family_tests_its_mean_action_at_the_edge_every_few_iterations(tmp_path):
    raw = _config(tmp_path, "edge", (0.7, 1.3)).model_dump()
    # 0.3 s episodes: too short to fall, so every test passes and the range grows each time
    raw["env"]["max_episode_seconds"] = 0.3
    raw["curriculum"]["widen"] = {"start": 0.3, "step": 0.2, "window": 5, "check_every": 2,
                                  "promote_on": "edge", "promote_below": 0.2}  # fmt: skip
    cfg = ExperimentConfig.model_validate(raw)
    trainer = Trainer(cfg, tmp_path / "edge")
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    rows = [trainer.iteration(backend) for _ in range(4)]
    backend.close()
    # tested after iterations 2 and 4 (0-based progress 1 -> 2, 3 -> 4), on 5 bodies of 9 steps
    assert [r.get("edge_fall_percent") for r in rows] == [None, 0.0, None, 0.0]
    assert [r.get("edge_env_steps") for r in rows] == [None, 45, None, 45]
    assert [r["range_width"] for r in rows] == pytest.approx([0.3, 0.5, 0.5, 0.7])
    assert trainer.progress.env_steps == 4 * 256  # the tests' steps are not training samples


def test_a_missing_source_fails_in_the_preflight_not_when_a_saved_config_is_read(tmp_path):
    cfg = _config(tmp_path, "family", (0.7, 1.3), init_from=str(tmp_path / "nowhere"))
    with pytest.raises(PreflightError, match="init_from: no checkpoint, run directory or shipped"):
        preflight(cfg)
    (tmp_path / "empty").mkdir()
    with pytest.raises(PreflightError, match="train.init_from: no checkpoint at"):
        preflight(_config(tmp_path, "family", (0.7, 1.3), init_from=str(tmp_path / "empty")))


def test_a_warm_started_run_evaluates_after_its_base_run_moved(tmp_path, base_run):
    from paramimic.evaluation import evaluate_config
    from paramimic.training import checkpoint

    cfg = _config(tmp_path, "family", (0.7, 1.3), init_from=str(tmp_path / "base"))
    preflight(cfg)
    family = Trainer(cfg, tmp_path / "family")
    family.save_checkpoint()
    (tmp_path / "base").rename(tmp_path / "elsewhere")  # the base run moved (or another node)
    state = checkpoint.load(tmp_path / "family")
    again = ExperimentConfig.model_validate(state["config"])  # re-read as eval, play, actors do
    assert again.train.init_from == tmp_path / "base"
    report = evaluate_config(family.learner.policy, again, 2, 0, 1, seconds=0.5)
    assert report["episodes"] == 2


def test_evaluate_config_runs_the_configs_env_task_space_and_horizon(tmp_path):
    from paramimic.evaluation import evaluate_config
    from paramimic.rl.networks import ActorCritic

    cfg = _config(tmp_path, "eval", (0.7, 1.3))
    env = env_for(cfg)
    policy = ActorCritic(env.observation_space.shape[0], env.action_space.shape[0], (16,), -1.0)
    report = evaluate_config(policy, cfg, 4, 0, 3, seconds=0.5)
    assert len(report["grid"]["returns"]) == 3 and report["grid"]["dims"] == [
        "left_leg_length",
        "right_leg_length",
    ]
    assert 0 < report["mean_return"] <= 15  # at most 15 steps of reward ≤ 1 in 0.5 s


def test_a_family_that_varies_more_than_its_base_starts_from_the_shipped_controller(tmp_path):
    """[WL19] Fig. 2b from the shipped humanoid_walk controller (`init_from: humanoid_walk`, a
    name): the family observes two task dims the controller never saw (each leg's length),
    inserted after its four; they start ignored, so on the base body the family's policy acts
    as the controller does, and the preflight finds the controller by name."""
    from paramimic.training import checkpoint

    source = checkpoint.load("humanoid_walk")
    base = ExperimentConfig.model_validate(source["config"])
    legs = {"left_leg_length": (0.9, 1.1), "right_leg_length": (0.9, 1.1)}
    family = base.model_copy(update={
        "task": dict(base.task) | legs,
        "train": base.train.model_copy(update={"init_from": "humanoid_walk", "torch_threads": 1}),
    })  # fmt: skip
    preflight(family)
    trainer = Trainer(family, tmp_path / "family")
    assert trainer.obs_dim == source["obs_dim"] + 2
    env = env_for(family)
    obs, _ = env.reset(seed=3, options={"task": [1.0] * 6})
    controller = Trainer(base.model_copy(update={"train": family.train.model_copy(
        update={"init_from": None})}), tmp_path / "base")  # fmt: skip
    controller.learner.policy.load_state_dict(source["learner"]["policy"])
    theirs = np.delete(obs, [4, 5])
    with torch.no_grad():
        mine = trainer.learner.policy(torch.as_tensor(obs[None]))[0].numpy()
        want = controller.learner.policy(torch.as_tensor(theirs[None]))[0].numpy()
    np.testing.assert_allclose(mine, want, rtol=1e-5, atol=1e-6)
