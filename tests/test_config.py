from pathlib import Path

import numpy as np
import pytest

from paramimic.config import ConfigError, load_config

CONFIG_DIR = Path(__file__).parent.parent / "configs"
CONFIGS = sorted(CONFIG_DIR.glob("*.yaml"))


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_shipped_configs_load(path):
    cfg = load_config(path)
    assert cfg.name == path.stem


def _write(tmp_path, text):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "text, field, reason",
    [
        ("task: {left_leg_length: [1.3, 0.7]}", "task.left_leg_length", "min 1.3 > max 0.7"),
        ("character: spider", "character", "unknown character 'spider'"),
        ("ppo: {policy_lr: -0.001}", "ppo.policy_lr", "greater than 0"),
        ("ppo: {num_stepz: 100}", "ppo.num_stepz", "Extra inputs are not permitted"),
        ("task: {arm_length: [0.8, 1.2]}", "task.arm_length", "not a parameter of 'walker'"),
        ("curriculum: {k: -1}", "curriculum.k", "greater than or equal to 0"),
        ("name: my run", "name", "should match pattern"),  # it starts the Redis run id
        # [WL19] §5.3: a planar body has no heading; the shape space is 'task' or 'full'
        ("task: {target_direction: [0, 1]}", "(config)", "sagittal plane only"),
        ("shape_space: all", "shape_space", "Input should be 'task' or 'full'"),
        # [L21] skill configs
        ("env: {clip: humanoid_jump}", "(config)", "does not fit character 'walker'"),
        (
            "env: {clip: planar_jump}\ntask: {gravity: [0.5, 1.5]}\n"
            "curriculum: {skill: {reference: {gravity: 2.0}}}",
            "(config)",
            "outside [0.5, 1.5]",
        ),
        (
            "curriculum: {skill: {density_visited: 0.1}}",
            "curriculum.skill",
            "must be below density_visited",
        ),
        ("env: {skill: {trace_bins: 1}}", "env.skill.trace_bins", "greater than or equal to 2"),
        ("env: {physics_hz: 200}", "env", "physics_hz (200) must be a multiple of control_hz"),
        ("train: {torch_threads: 0}", "train.torch_threads", "must be >= 1 or 'auto'"),
        ("env: {physics_hz: 300, frame_skip: 20}", "env", "frame_skip 20 != physics_hz"),
        # no NaN/inf anywhere, shapes within what the character supports, seeds >= 0
        ("ppo: {gamma: .nan}", "ppo.gamma", "finite number"),
        ("curriculum: {k: .inf}", "curriculum.k", "finite number"),
        ("task: {left_leg_length: [0.8, .inf]}", "task.left_leg_length", "finite number"),
        ("task: {left_leg_length: [0.8, 2.5]}", "task.left_leg_length", "supports, [0.5, 1.5]"),
        ("train: {seed: -1}", "train.seed", "greater than or equal to 0"),
        # a family's shape ranges shrunk toward the base body
        ("shape_scale: 0.5", "(config)", "shape_scale: shrinks the documented shape ranges"),
        ("shape_space: full\nshape_scale: 1.5", "shape_scale", "less than or equal to 1"),
        # upper bounds: refused before anything starts, not after Redis and Ray are up
        ("ppo: {hidden_sizes: [1000000000]}", "ppo.hidden_sizes", "less than or equal to 4096"),
        ("curriculum: {marginal_hidden: [-5]}", "curriculum.marginal_hidden", "greater than"),
        ("curriculum: {marginal_hidden: [0]}", "curriculum.marginal_hidden", "greater than"),
        ("curriculum: {marginal_hidden: []}", "curriculum.marginal_hidden", "at least 1 item"),
        ("train: {seed: 1208925819614629174706176}", "train.seed", "less than or equal to"),
        ("ppo: {init_log_std: 1.0e300}", "ppo.init_log_std", "less than or equal to 2"),
        ("task: {target_velocity: [-1.0e300, 1.0e300]}", "task.target_velocity", "leaves [-20"),
    ],
)
def test_bad_configs_name_the_field(tmp_path, text, field, reason):
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, text))
    assert field in str(err.value)
    assert reason in str(err.value)


def test_unreadable_yaml(tmp_path):
    with pytest.raises(ConfigError, match="cannot read config"):
        load_config(_write(tmp_path, "task: [unclosed"))


def test_physics_rate_defaults_to_the_characters_and_old_configs_keep_theirs(tmp_path):
    from paramimic.characters import registration

    cfg = load_config(_write(tmp_path, "character: quadruped"))
    assert cfg.env.physics_hz == registration("quadruped").physics_hz
    assert cfg.env.frame_skip == cfg.env.physics_hz // 30
    # a config written before physics_hz existed names frame_skip: its rate stays 30 x that
    old = load_config(_write(tmp_path, "character: quadruped\nenv: {frame_skip: 20}"))
    assert (old.env.physics_hz, old.env.frame_skip) == (600, 20)
    chosen = load_config(_write(tmp_path, "character: quadruped\nenv: {physics_hz: 150}"))
    assert chosen.env.frame_skip == 5


def test_a_clip_with_no_velocity_term_is_performed_in_place(tmp_path):
    """`env.reward.in_place` (no speed to hold) is the COM-velocity weight set to 0, not left to
    the character's [WL19] Table 3 row."""
    assert load_config(CONFIG_DIR / "humanoid_dance.yaml").env.reward.in_place
    assert not load_config(CONFIG_DIR / "humanoid_walk.yaml").env.reward.in_place
    cfg = load_config(_write(tmp_path, "character: humanoid\nenv: {reward: {w_com_velocity: 0.5}}"))
    assert not cfg.env.reward.in_place


def test_shape_scale_shrinks_every_documented_range_toward_the_base_body(tmp_path):
    """`shape_scale` s: [1 - s(1 - lo), 1 + s(hi - 1)] per shape parameter; a `task` entry still
    overrides its range; 0 is the base body alone."""
    from paramimic.characters import get_character

    params = get_character("quadruped").shape_params
    half = load_config(
        _write(tmp_path, "character: quadruped\nshape_space: full\nshape_scale: 0.5\n"
               "task: {head_x: [0.9, 1.0]}")
    )  # fmt: skip
    for p in params:
        want = (0.9, 1.0) if p.name == "head_x" else (1 - (1 - p.low) / 2, 1 + (p.high - 1) / 2)
        assert half.task[p.name] == pytest.approx(want), p.name
    assert half.task["global_x"] == pytest.approx((0.75, 1.25))  # [WL19] §5.3's 0.5-1.5, halved
    base = load_config(_write(tmp_path, "character: quadruped\nshape_space: full\nshape_scale: 0"))
    assert all(base.task[p.name] == (1.0, 1.0) for p in params)


@pytest.mark.parametrize("character", ["quadruped", "biped"])
def test_a_x05_family_config_is_its_base_stage_widened(character):
    """configs/<character>_x0.5.yaml warm starts from configs/<character>_base.yaml's run: the
    same body, rules and PPO but for what the family stage adds
    (docs/results/families-that-learn.md): retargeted legs, the small step, and for the biped
    a range grown from the base."""
    root = Path(__file__).parent.parent / "configs"
    base = load_config(root / f"{character}_base.yaml").model_dump()
    family = load_config(root / f"{character}_x0.5.yaml").model_dump()
    assert (base["shape_scale"], family["shape_scale"]) == (0.0, 0.5)
    assert (base["env"]["retarget"], family["env"]["retarget"]) == (False, True)
    assert (base["ppo"]["desired_kl"], family["ppo"]["desired_kl"]) == (None, 0.01)
    assert base["curriculum"]["widen"] is None
    widen = family["curriculum"]["widen"]
    if character == "biped":
        assert (widen["start"], widen["step"], widen["promote_on"]) == (0.05, 0.05, "falls")
    else:
        assert widen is None
    for cfg in (base, family):
        del cfg["name"], cfg["task"], cfg["shape_scale"], cfg["env"]["retarget"]
        del cfg["ppo"]["desired_kl"], cfg["train"]["total_steps"], cfg["curriculum"]["widen"]
    assert base == family


SKILL_CONFIGS = [p for p in CONFIGS if "clip:" in p.read_text()]


@pytest.mark.parametrize("path", SKILL_CONFIGS, ids=lambda p: p.name)
def test_shipped_skill_families_build_with_their_declared_measures(path):
    """Each shipped [L21] family builds its env; every declared parameter is measured
    (a0 from the clip inside the task box, `reference` units at 1)."""
    import yaml

    from paramimic.envs.skill_env import SkillEnv

    cfg = load_config(path)
    declared = {
        k for k, v in yaml.safe_load(path.read_text())["task"].items() if isinstance(v, dict)
    }
    assert set(cfg.env.skill.measures) == declared
    env = SkillEnv(cfg.character, cfg.task, cfg.env)
    a0 = env.reference_task()
    assert env.task_space.contains(a0).all()
    for t in env.measured:
        if t.measure.unit == "reference":
            assert a0[t.index] == pytest.approx(np.clip(1.0, *cfg.task[t.name]))
