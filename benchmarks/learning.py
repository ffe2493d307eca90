"""Learning quality: paramimic PPO vs Stable-Baselines3 PPO, and adaptive sampling k=0 vs k=10.

Stages (each writes benchmarks/results/learning_<stage>.json; `all` runs them two at a time and
merges them into benchmarks/results/learning.json):
- `ours_base`: train configs/walker_base.yaml for --steps, evaluate 300 episodes.
- `sb3_base`: SB3 PPO on the same gymnasium env (paramimic/Walker-v0, same env section) for the
  same steps, with the same PPO hyperparameters (γ, λ, clip, lr, 4096 steps/update as 16 envs x
  256, minibatch 512, 10 epochs, 3x128 ReLU nets, observation normalization via VecNormalize);
  evaluated by the same episode runner, tasks and seeds.
- `legs_k0`, `legs_k10`: configs/walker_legs.yaml with curriculum.k = 0 and 10 at equal budget;
  fall % over 300 random shapes, worst-decile return, uniformity over random shapes and the grid.

    pip install -e ".[bench]"; python benchmarks/learning.py all [--steps 1000000]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
STAGES = ("ours_base", "sb3_base", "legs_k0", "legs_k10")
EVAL_EPISODES = int(__import__("os").environ.get("EVAL_EPISODES", 300))
EVAL_SEED = 2024


def _train_ours(config: str, steps: int, overrides: dict, run_dir: Path) -> dict:
    import torch

    from paramimic.config import load_config
    from paramimic.envs import make_env
    from paramimic.evaluation import deterministic, evaluate
    from services.learner.trainer import SerialBackend, Trainer

    cfg = load_config(ROOT / config, {**overrides, "train.run_dir": str(run_dir)})
    torch.manual_seed(cfg.train.seed)
    run_dir.mkdir(parents=True, exist_ok=True)
    trainer = Trainer(cfg, run_dir)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.sampler.next_tasks)
    t0 = time.perf_counter()
    trainer.train(backend, steps)
    train_seconds = time.perf_counter() - t0
    report = evaluate(
        deterministic(trainer.learner.policy),
        lambda: make_env(cfg.character, cfg.task, cfg.env),
        trainer.space,
        EVAL_EPISODES,
        EVAL_SEED,
        cfg.grid_dims(),
        5,
    )
    report.update(
        {
            "env_steps": trainer.progress.env_steps,
            "train_seconds": train_seconds,
            "config": config,
            "overrides": overrides,
            "target_velocity": cfg.task.get("target_velocity", [cfg.env.target_velocity])[0],
        }
    )
    return report


def _train_sb3(steps: int, run_dir: Path) -> dict:
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    import paramimic.envs  # noqa: F401
    from paramimic.config import load_config
    from paramimic.envs import make_env
    from paramimic.evaluation import evaluate

    cfg = load_config(ROOT / "configs/walker_base.yaml")
    torch.set_num_threads(1)
    env_kwargs = {"config": cfg.env.model_dump()}

    def make():
        return gym.make("paramimic/Walker-v0", **env_kwargs)

    venv = VecNormalize(
        DummyVecEnv([make] * cfg.actors.num_envs),
        norm_obs=True,
        norm_reward=False,
        gamma=cfg.ppo.gamma,
    )
    p = cfg.ppo
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=p.num_steps // cfg.actors.num_envs,
        batch_size=p.minibatch_size,
        n_epochs=p.num_epochs,
        gamma=p.gamma,
        gae_lambda=p.gae_lambda,
        clip_range=p.clip_coef,
        learning_rate=p.policy_lr,
        ent_coef=p.ent_coef,
        vf_coef=p.vf_coef,
        max_grad_norm=p.max_grad_norm,
        policy_kwargs={
            "net_arch": {"pi": list(p.hidden_sizes), "vf": list(p.hidden_sizes)},
            "activation_fn": torch.nn.ReLU,
            "log_std_init": p.init_log_std,
        },
        seed=cfg.train.seed,
        device="cpu",
        verbose=0,
    )
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    train_seconds = time.perf_counter() - t0
    venv.training = False
    run_dir.mkdir(parents=True, exist_ok=True)
    model.save(run_dir / "sb3_ppo")

    def act(obs: np.ndarray) -> np.ndarray:
        return model.predict(venv.normalize_obs(obs), deterministic=True)[0]

    probe = make_env(cfg.character, cfg.task, cfg.env)
    report = evaluate(
        act,
        lambda: make_env(cfg.character, cfg.task, cfg.env),
        probe.task_space,
        EVAL_EPISODES,
        EVAL_SEED,
        None,
        1,
    )
    report.update(
        {
            "env_steps": int(model.num_timesteps),
            "train_seconds": train_seconds,
            "config": "configs/walker_base.yaml (SB3 PPO)",
            "target_velocity": 1.0,
        }
    )
    return report


def run_stage(stage: str, steps: int) -> dict:
    warnings.filterwarnings("ignore")
    run_dir = ROOT / "runs" / "bench" / stage
    shutil.rmtree(run_dir, ignore_errors=True)  # a stage always trains from scratch
    if stage == "ours_base":
        report = _train_ours("configs/walker_base.yaml", steps, {}, run_dir)
    elif stage == "sb3_base":
        report = _train_sb3(steps, run_dir)
    elif stage in ("legs_k0", "legs_k10"):
        k = 0.0 if stage == "legs_k0" else 10.0
        report = _train_ours("configs/walker_legs.yaml", steps, {"curriculum.k": k}, run_dir)
    else:
        raise SystemExit(f"unknown stage {stage}; stages: {STAGES}")
    report["stage"] = stage
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"learning_{stage}.json").write_text(json.dumps(report, indent=2))
    return report


def merge() -> dict:
    stages = {
        s: json.loads((RESULTS / f"learning_{s}.json").read_text())
        for s in STAGES
        if (RESULTS / f"learning_{s}.json").exists()
    }
    summary: dict = {"stages": stages}
    if {"ours_base", "sb3_base"} <= stages.keys():
        ours, sb3 = stages["ours_base"], stages["sb3_base"]
        speed_err = (
            abs(ours["mean_forward_speed"] - ours["target_velocity"]) / ours["target_velocity"]
        )
        summary["walker_base"] = {
            "ours_return": ours["mean_return"],
            "sb3_return": sb3["mean_return"],
            "ours_ge_sb3": ours["mean_return"] >= sb3["mean_return"],
            "ours_fall_percent": ours["fall_percent"],
            "sb3_fall_percent": sb3["fall_percent"],
            "fall_le_10": ours["fall_percent"] <= 10.0,
            "ours_forward_speed": ours["mean_forward_speed"],
            "speed_error_fraction": speed_err,
            "speed_within_25pc": speed_err <= 0.25,
        }
    if {"legs_k0", "legs_k10"} <= stages.keys():
        summary["walker_legs"] = {
            s: {
                "fall_percent": stages[s]["fall_percent"],
                "worst_decile_return": stages[s]["worst_decile_return"],
                "mean_return": stages[s]["mean_return"],
                "uniformity_random": stages[s]["uniformity"],
                "uniformity_grid": stages[s].get("grid", {}).get("uniformity"),
            }
            for s in ("legs_k0", "legs_k10")
        }
    (RESULTS / "learning.json").write_text(json.dumps(summary, indent=2))
    return summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("stage", choices=[*STAGES, "all", "merge"])
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--parallel", type=int, default=2)
    args = ap.parse_args()
    if args.stage == "merge":
        pass
    elif args.stage == "all":

        def sub(stage: str) -> int:
            return subprocess.call([sys.executable, __file__, stage, "--steps", str(args.steps)])

        with ThreadPoolExecutor(args.parallel) as pool:
            codes = list(pool.map(sub, STAGES))
        if any(codes):
            raise SystemExit(f"stage exit codes: {dict(zip(STAGES, codes, strict=True))}")
    else:
        run_stage(args.stage, args.steps)
    print(json.dumps({k: v for k, v in merge().items() if k != "stages"}, indent=2))


if __name__ == "__main__":
    main()
