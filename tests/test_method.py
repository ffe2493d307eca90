"""Training methods: each config has one (`method_for`), and a new method is one subclass and
one registration; the trainer then runs it, checkpoints its parts and resumes them."""

import numpy as np
import pytest

from paramimic.config import ExperimentConfig
from paramimic.curriculum.adaptive import AdaptiveCurriculum
from paramimic.curriculum.skill import SkillCurriculum
from paramimic.training import method as methods
from paramimic.training.method import L21, WL19, Method, method_for, register
from paramimic.training.trainer import SerialBackend, Trainer

TINY = {
    "ppo": {"num_steps": 128, "minibatch_size": 64, "num_epochs": 1, "hidden_sizes": [16]},
    "actors": {"num_envs": 2},
    "env": {"max_episode_seconds": 0.5},
}


def test_each_shipped_kind_of_config_has_its_method():
    walker = ExperimentConfig.model_validate({"task": {"left_leg_length": [0.9, 1.1]}})
    skill = ExperimentConfig.model_validate(
        {"task": {"gravity": [0.5, 1.5]}, "env": {"clip": "planar_jump"}}
    )
    assert type(method_for(walker)) is WL19 and type(method_for(skill)) is L21
    assert isinstance(method_for(walker).new_curriculum(), AdaptiveCurriculum)
    spaces = method_for(skill).spaces
    assert spaces.trace_shape == (16, spaces.act_dim + 3)  # (d_root [3 planar], d, τ) per bin
    assert isinstance(method_for(skill).new_curriculum(spaces.clip_setup()), SkillCurriculum)
    assert method_for(walker).learner_parts(0) == {}
    assert set(method_for(skill).learner_parts(0)) == {"motion_net", "bootstrap"}


class Counter:
    """A learner part of the toy method: what it saw, checkpointed."""

    def __init__(self) -> None:
        self.updates, self.returns = 0, []

    def to_state(self) -> dict:
        return {"updates": self.updates, "returns": list(self.returns)}

    def from_state(self, state: dict) -> None:
        self.updates, self.returns = state["updates"], list(state["returns"])


class UniformBodies(Method):
    """A toy method: [WL19]'s env with tasks always uniform over the box (the curriculum's own
    k = 0 baseline), counting its updates."""

    name = "uniform_bodies"

    @classmethod
    def applies(cls, cfg):
        return cfg.name == "toy_uniform"

    def new_curriculum(self, clip=None):
        cfg = self.cfg.model_copy(update={"curriculum": self.cfg.curriculum.model_copy(
            update={"k": 0.0})})  # fmt: skip
        return AdaptiveCurriculum.from_config(cfg)

    def learner_parts(self, seed):
        return {"counter": Counter()}

    def after_update(self, trainer, metrics):
        counter = trainer.parts["counter"]
        counter.updates += 1
        counter.returns.append(metrics.get("mean_return"))
        return {"toy_updates": counter.updates}


@pytest.fixture
def toy():
    register(UniformBodies)  # the one line
    yield UniformBodies
    methods.METHODS.remove(UniformBodies)


def test_a_new_method_is_one_class_and_one_registration(toy, tmp_path):
    cfg = ExperimentConfig.model_validate(
        TINY | {"name": "toy_uniform", "task": {"left_leg_length": [0.8, 1.2]}}
    )
    trainer = Trainer(cfg, tmp_path)
    assert isinstance(trainer.method, UniformBodies) and trainer.curriculum.mode == "uniform"
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    metrics = []
    trainer.train(backend, total_steps=2 * 128, on_metrics=metrics.append)
    assert [m["toy_updates"] for m in metrics] == [1, 2]
    state = trainer.state_dict()
    assert state["counter"]["updates"] == 2
    again = Trainer(cfg, tmp_path)
    again.load_state_dict(state)
    assert again.parts["counter"].updates == 2
    assert np.allclose(again.parts["counter"].returns, trainer.parts["counter"].returns)
    other = ExperimentConfig.model_validate(TINY | {"task": {"left_leg_length": [0.8, 1.2]}})
    assert type(method_for(other)) is WL19  # the toy applies to its own configs only


@pytest.mark.parametrize(
    "data, reason",
    [
        ({"character": "humanoid"}, "character: 'humanoid' has no procedural [WL19] gait"),
        ({"task": {"gravity": [0.5, 1.5]}}, "task.gravity: needs env.clip"),
        ({"env": {"clip": "planar_jump"}, "task": {"target_velocity": [1, 1]}}, "gait goal"),
        ({"env": {"clip": "planar_jump"}, "curriculum": {"widen": {}}}, "curriculum.widen:"),
        ({"env": {"clip": "planar_jump", "retarget": True}}, "env.retarget:"),
        ({"env": {"deviation_limit": 0.5}}, "env.deviation_limit:"),
        ({"env": {"clip": "planar_jump", "phase_sampling": "failures"}}, "env.phase_sampling:"),
    ],
)
def test_each_method_refuses_what_it_cannot_run_naming_the_field(data, reason):
    """The rules of a method live with it: the config's data is valid, the method says no."""
    from paramimic.config import ConfigError

    cfg = ExperimentConfig.model_validate(data | {"name": "rules"})
    with pytest.raises(ConfigError) as err:
        method_for(cfg)
    assert str(err.value).startswith("rules: ") and reason in str(err.value)
