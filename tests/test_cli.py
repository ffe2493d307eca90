"""The `paramimic` command as a user runs it: a real subprocess, real files."""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import yaml
from conftest import wait_until

TINY = {
    "character": "hopper",
    "task": {"leg_length": [0.8, 1.2], "torso_length": [0.9, 1.1], "target_velocity": [1, 1]},
    "env": {"max_episode_seconds": 2.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
    "actors": {"num_envs": 4},
    "train": {"total_steps": 512, "checkpoint_every": 1},
}


def _cli(*args, **kw):
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        **kw,
    )


def _train_serial(tmp_path: Path, config: dict) -> tuple[Path, Path]:
    """`paramimic train CONFIG --serial` to the end; (config file, run dir)."""
    cfg, run = tmp_path / "config.yaml", tmp_path / "run"
    cfg.write_text(yaml.safe_dump(config))
    res = _cli("train", cfg, "--serial", "--run-dir", run)
    assert res.returncode == 0, res.stdout + res.stderr
    return cfg, run


def test_train_then_eval_writes_json(tmp_path):
    cfg, run = _train_serial(tmp_path, TINY)
    assert (run / "checkpoints" / "latest.pt").is_file()
    lines = (run / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["iteration"] for x in lines] == [1, 2]

    out = tmp_path / "eval.json"
    res = _cli("eval", run, "--episodes", 6, "--grid", 2, "--seed", 1, "--out", out)
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads(out.read_text())
    assert report["episodes"] == 6
    for key in ("mean_return", "task_achievement", "fall_percent", "worst_decile_return"):
        assert isinstance(report[key], float)
    assert 0 <= report["fall_percent"] <= 100
    assert set(report["uniformity"]) == {"min_over_mean", "coefficient_of_variation"}
    assert report["grid"]["dims"] == ["leg_length", "torso_length"]
    assert len(report["grid"]["returns"]) == 2 and len(report["grid"]["returns"][0]) == 2

    res = _cli("train", cfg, "--serial", "--run-dir", run, "--resume", "--total-steps", 768)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "resumed at iteration 2" in res.stdout
    assert json.loads((run / "metrics.jsonl").read_text().splitlines()[-1])["iteration"] == 3

    # a resume that would change the body or the env is refused, naming the fields
    changed = TINY | {"task": TINY["task"] | {"leg_length": [0.7, 1.2]}}
    changed |= {"env": {"max_episode_seconds": 3.0}}
    cfg.write_text(yaml.safe_dump(changed))
    res = _cli("train", cfg, "--serial", "--run-dir", run, "--resume", "--total-steps", 1024)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "env.max_episode_seconds: 2.0 -> 3.0" in res.stdout + res.stderr
    assert "task" in res.stdout + res.stderr
    assert len((run / "metrics.jsonl").read_text().splitlines()) == 3  # nothing ran


def test_resume_if_exists_starts_a_new_run_then_continues_it(tmp_path):
    """What the compose learner runs on every (re)start."""
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump(TINY))
    run = tmp_path / "run"
    res = _cli("train", cfg, "--serial", "--run-dir", run, "--resume-if-exists")
    assert res.returncode == 0, res.stdout + res.stderr
    assert "resumed" not in res.stdout
    res = _cli("train", cfg, "--serial", "--run-dir", run, "--resume-if-exists",
               "--total-steps", 768)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    assert "resumed at iteration 2" in res.stdout


def test_a_family_trains_from_its_base_stage_with_init_from(tmp_path):
    """The two-stage recipe of configs/quadruped_base.yaml -> quadruped_x0.5.yaml as a user runs
    it: the base body alone (shape_scale 0), then the family from its controller."""
    stage = TINY | {"task": {"target_velocity": [1, 1]}, "shape_space": "full"}
    base_cfg, family_cfg = tmp_path / "base.yaml", tmp_path / "family.yaml"
    base_cfg.write_text(yaml.safe_dump(stage | {"shape_scale": 0.0}))
    family_cfg.write_text(yaml.safe_dump(stage | {"shape_scale": 0.5}))
    base, family = tmp_path / "base", tmp_path / "family"
    # a source that is not there fails before anything starts, naming the field
    res = _cli("train", family_cfg, "--serial", "--run-dir", family, "--init-from", tmp_path / "x")
    assert res.returncode == 2, res.stdout + res.stderr
    assert "train.init_from: no checkpoint, run directory or shipped controller" in res.stdout
    assert not family.exists()
    for cfg, run, more in ((base_cfg, base, ()), (family_cfg, family, ("--init-from", base))):
        res = _cli("train", cfg, "--serial", "--run-dir", run, *more)
        assert res.returncode == 0, res.stdout + res.stderr
    import torch

    state = torch.load(family / "checkpoints" / "latest.pt", weights_only=False)
    assert state["config"]["train"]["init_from"] == str(base)
    assert state["config"]["task"]["leg_length"] == [0.75, 1.25]  # the hopper's 0.5-1.5, halved
    first = torch.load(base / "checkpoints" / "latest.pt", weights_only=False)
    assert first["config"]["task"]["leg_length"] == [1.0, 1.0]


SKILL = {
    "character": "walker",
    "task": {"gravity": [0.5, 1.5], "jump_height": [0.0, 0.6]},
    "env": {"clip": "planar_jump"},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
    "curriculum": {"skill": {"batch_size": 4, "episodes_per_param": 2, "p_every": 1,
                             "base_min_iterations": 1, "base_max_iterations": 1}},
    "actors": {"num_envs": 4},
    "train": {"total_steps": 768, "checkpoint_every": 1},
}  # fmt: skip


def test_skill_run_trains_resumes_and_evaluates(tmp_path):
    """An [L21] run in one process: the bootstrap stage, P_θ and the elites survive --resume."""
    cfg, run = _train_serial(tmp_path, SKILL)
    lines = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    assert [m["stage"] for m in lines] == ["proxy", "proxy", "proxy"]
    res = _cli("train", cfg, "--serial", "--run-dir", run, "--resume", "--total-steps", 1024)
    assert res.returncode == 0, res.stdout + res.stderr
    last = json.loads((run / "metrics.jsonl").read_text().splitlines()[-1])
    assert last["iteration"] == 4 and last["stage"] in ("proxy", "mixed")  # not back to base
    assert last["motion_version"] >= lines[-1]["motion_version"]
    out = tmp_path / "eval.json"
    res = _cli("eval", run, "--episodes", 4, "--grid", 2, "--seed", 1, "--out", out)
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads(out.read_text())
    assert 0.0 <= report["mean_fitness"] <= 1.1 and 0 <= report["fall_percent"] <= 100
    assert report["grid"]["dims"] == ["gravity", "jump_height"]
    # each task performed with the run's m_a (the proxy or P_θ) and judged by its σ_task
    assert 0.0 <= report["achieved_share"] <= 1.0
    assert set(report["task_error_sigmas"]) == {"jump_height"}


def test_bad_config_fails_before_anything_starts(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(yaml.safe_dump({**TINY, "ppo": {"policy_lr": -1}}))
    res = _cli("train", cfg, "--serial", "--run-dir", tmp_path / "run")
    assert res.returncode == 2
    assert "ppo.policy_lr" in res.stdout and "greater than 0" in res.stdout
    assert not (tmp_path / "run").exists()


def test_train_set_overrides_any_field_and_a_bad_one_fails_naming_it(tmp_path):
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump(TINY))
    run = tmp_path / "run"
    res = _cli(
        "train", cfg, "--serial", "--run-dir", run, "--total-steps", 256,
        "--set", "curriculum.k=0", "--set", "name=tiny_uniform", "--set", "ppo.num_epochs=1",
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    saved = yaml.safe_load((run / "config.yaml").read_text())
    assert saved["name"] == "tiny_uniform" and saved["curriculum"]["k"] == 0
    assert saved["ppo"]["num_epochs"] == 1
    res = _cli("train", cfg, "--serial", "--run-dir", tmp_path / "r2", "--set", "ppo.num_epochs")
    assert res.returncode == 2 and "KEY=VALUE" in res.stdout
    res = _cli("train", cfg, "--serial", "--run-dir", tmp_path / "r2", "--set", "ppo.num_epochs=0")
    assert res.returncode == 2 and "ppo.num_epochs" in res.stdout
    assert not (tmp_path / "r2").exists()


def test_ctrl_c_checkpoints_and_exits(tmp_path):
    cfg = tmp_path / "long.yaml"
    cfg.write_text(
        yaml.safe_dump({**TINY, "train": {"total_steps": 10**9, "checkpoint_every": 1000}})
    )
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "services.cli",
            "train",
            str(cfg),
            "--serial",
            "--run-dir",
            str(run),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ},
    )
    metrics = Path(run / "metrics.jsonl")
    wait_until(lambda: metrics.exists() and metrics.read_text().strip(), 120, "a first iteration")
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0, out
    assert (run / "checkpoints" / "latest.pt").is_file()


def test_train_without_serial_runs_on_a_local_ray(tmp_path):
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump({**TINY, "actors": {"num_actors": 1, "num_envs": 4}}))
    run = tmp_path / "run"
    res = _cli("train", cfg, "--run-dir", run, "--api-port", "0",  # any free port
               env={**os.environ, "RAY_ADDRESS": ""})  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Ray: 1 rollout actors x 4 envs" in res.stdout
    last = json.loads((run / "metrics.jsonl").read_text().splitlines()[-1])
    assert last["iteration"] == 2 and last["actors"] == 1 and last["actor_restarts"] == 0


def test_eval_runs_whole_episodes_without_the_training_only_stall_rule(tmp_path):
    """A run trained with a stall rule (a fish that never falls, ended in training once its
    0.5-s average speed is below its target speed) is evaluated on whole episodes."""
    fish = {
        "character": "fish",
        "task": {"target_velocity": [1, 1]},
        "env": {
            "imitation": False,
            "max_episode_seconds": 2.0,
            "com_velocity_window": 0.5,
            "stall_speed_ratio": 1.0,
        },
        "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 1},
        "actors": {"num_envs": 4},
        "train": {"total_steps": 512, "checkpoint_every": 1},
    }
    _, run = _train_serial(tmp_path, fish)
    metrics = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    assert max(m["mean_length"] for m in metrics) < 0.5 * 2.0 * 30  # training episodes stalled
    out = tmp_path / "eval.json"
    res = _cli("eval", run, "--episodes", 4, "--grid", 1, "--seed", 1, "--out", out)
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads(out.read_text())
    assert report["fall_percent"] == 0.0
    assert report["mean_length_seconds"] == 2.0  # every episode to its horizon
