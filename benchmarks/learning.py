"""Learning quality: paramimic PPO vs Stable-Baselines3 PPO, and adaptive sampling k=0 vs k=10.

Stages (each writes benchmarks/results/learning/learning_<stage>_s<seed>.json; `all` runs them for
every --seeds, two at a time, and merges them into benchmarks/results/learning/learning.json):
- `ours_base`: train configs/walker_base.yaml for --steps, evaluate 300 episodes.
- `sb3_base`: SB3 PPO on the same gymnasium env (paramimic/Walker-v0, same env section) for the
  same steps, with the same PPO hyperparameters (γ, λ, clip, lr, 4096 steps/update as 16 envs x
  256, minibatch 512, 10 epochs, 3x128 ReLU nets, observation normalization via VecNormalize);
  evaluated by the same episode runner, tasks and seeds.
- `legs_k0`, `legs_k10`: configs/walker_legs.yaml with curriculum.k = 0 and 10 at equal budget;
  fall % over 300 random shapes, worst-decile return, uniformity over random shapes and the grid.
- `ray_sync_base`, `ray_pipelined_base` (not part of `all`): walker_base trained on a local Ray
  with 2 actors x 8 envs in sync and in pipelined mode, to compare their learning.

    pip install -e ".[bench]"; python benchmarks/learning.py all [--steps 1000000] [--seeds 0,1,2]
    python benchmarks/learning.py ours_base --seed 1     # one stage
    python benchmarks/learning.py merge                  # summarize what is there
    python benchmarks/learning.py targets [--run]        # the family targets' rows (below)

`targets` reads the result files behind each of the family targets (walker_legs within 5M, adaptive
vs uniform, biped_lower and quadruped at x0.5 ranges, the base biped at 2M, [L21] walker_jump's
explored ratio, `make train`'s end) and writes benchmarks/results/learning/targets.json: per row the
target, the measurement, the seeds it rests on, met or missed, and the command that makes it.
With --run, the commands of rows whose results are missing run first (resumable; long).
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
RESULTS = ROOT / "benchmarks" / "results" / "learning"
STAGES = ("ours_base", "sb3_base", "legs_k0", "legs_k10")
RAY_STAGES = ("ray_sync_base", "ray_pipelined_base")  # 2 actors x 8 envs on a local Ray
EVAL_EPISODES = int(__import__("os").environ.get("EVAL_EPISODES", 300))
EVAL_SEED = 2024


def _train_ours(
    config: str,
    steps: int,
    overrides: dict,
    run_dir: Path,
    seed: int,
    on_ray: bool = False,
    eval_seconds: float | None = None,
) -> dict:
    import torch

    from paramimic.config import load_config
    from paramimic.evaluation import evaluate_config
    from paramimic.training.trainer import train_serial

    cfg = load_config(
        ROOT / config, {**overrides, "train.run_dir": str(run_dir), "train.seed": seed}
    )
    torch.manual_seed(cfg.train.seed)
    run_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if on_ray:
        import ray

        from services.launch.redis_server import EmbeddedRedis
        from services.launch.stack import ray_stack
        from services.learner.cluster import start_private

        start_private()  # a cluster of its own, as `paramimic train` starts
        try:
            with (
                EmbeddedRedis(run_dir / "redis") as server,
                ray_stack(cfg, run_dir, server.url, f"bench-{run_dir.name}") as stack,
            ):
                trainer = stack.trainer
                t0 = time.perf_counter()
                trainer.train(stack.backend, steps)
        finally:
            ray.shutdown()
    else:
        trainer = train_serial(cfg, steps, run_dir)
    train_seconds = time.perf_counter() - t0
    report = evaluate_config(
        trainer.learner.policy, cfg, EVAL_EPISODES, EVAL_SEED, 5, seconds=eval_seconds
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


def _train_sb3(steps: int, run_dir: Path, seed: int) -> dict:
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    import paramimic.envs  # noqa: F401
    from paramimic.config import load_config
    from paramimic.envs import env_for
    from paramimic.evaluation import evaluate

    cfg = load_config(ROOT / "configs/walker_base.yaml", {"train.seed": seed})
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

    env_cfg = cfg.env.for_evaluation()
    probe = env_for(cfg, env_cfg)
    report = evaluate(
        act,
        lambda: env_for(cfg, env_cfg),
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


def run_stage(stage: str, steps: int, seed: int) -> dict:
    warnings.filterwarnings("ignore")
    run_dir = ROOT / "runs" / "bench" / f"{stage}_s{seed}"
    shutil.rmtree(run_dir, ignore_errors=True)  # a stage always trains from scratch
    if stage == "ours_base":
        report = _train_ours("configs/walker_base.yaml", steps, {}, run_dir, seed)
    elif stage == "sb3_base":
        report = _train_sb3(steps, run_dir, seed)
    elif stage in ("legs_k0", "legs_k10"):
        k = 0.0 if stage == "legs_k0" else 10.0
        report = _train_ours("configs/walker_legs.yaml", steps, {"curriculum.k": k}, run_dir, seed)
    elif stage in ("ray_sync_base", "ray_pipelined_base"):
        mode = "sync" if stage == "ray_sync_base" else "pipelined"
        overrides = {"actors.mode": mode, "actors.num_actors": 2, "actors.num_envs": 8}
        report = _train_ours("configs/walker_base.yaml", steps, overrides, run_dir, seed, True)
    else:
        raise SystemExit(f"unknown stage {stage}; stages: {STAGES + RAY_STAGES}")
    report.update({"stage": stage, "seed": seed})
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"learning_{stage}_s{seed}.json").write_text(json.dumps(report, indent=2))
    return report


def _mean(runs: list[dict], key: str) -> float:
    return float(np.mean([r[key] for r in runs]))


def merge() -> dict:
    runs: dict[str, list[dict]] = {}
    for path in sorted(RESULTS.glob("learning_*_s*.json")):
        report = json.loads(path.read_text())
        runs.setdefault(report["stage"], []).append(report)
    summary: dict = {"runs": {k: [_brief(r) for r in v] for k, v in runs.items()}}
    if {"ours_base", "sb3_base"} <= runs.keys():
        ours, sb3 = runs["ours_base"], runs["sb3_base"]
        speed = _mean(ours, "mean_forward_speed")
        target = ours[0]["target_velocity"]
        summary["walker_base"] = {
            "seeds": {"ours": [r["seed"] for r in ours], "sb3": [r["seed"] for r in sb3]},
            "ours_return": _mean(ours, "mean_return"),
            "sb3_return": _mean(sb3, "mean_return"),
            "ours_ge_sb3": _mean(ours, "mean_return") >= _mean(sb3, "mean_return"),
            "ours_fall_percent": _mean(ours, "fall_percent"),
            "sb3_fall_percent": _mean(sb3, "fall_percent"),
            "fall_le_10": _mean(ours, "fall_percent") <= 10.0,
            "ours_forward_speed": speed,
            "speed_error_fraction": abs(speed - target) / target,
            "speed_within_25pc": abs(speed - target) / target <= 0.25,
            "ours_train_seconds": _mean(ours, "train_seconds"),
            "sb3_train_seconds": _mean(sb3, "train_seconds"),
        }
    if {"ray_sync_base", "ray_pipelined_base"} <= runs.keys():
        summary["ray_modes"] = {
            k: {
                "mean_return": _mean(runs[k], "mean_return"),
                "fall_percent": _mean(runs[k], "fall_percent"),
                "train_seconds": _mean(runs[k], "train_seconds"),
                "steps_per_second": _mean(runs[k], "env_steps") / _mean(runs[k], "train_seconds"),
            }
            for k in ("ray_sync_base", "ray_pipelined_base")
        }
    for k in ("legs_k0", "legs_k10"):
        by_budget: dict[int, list[dict]] = {}
        for r in runs.get(k, []):  # runs of different budgets are compared, never averaged
            by_budget.setdefault(round(r["env_steps"] / 1e6), []).append(r)
        for millions, group in sorted(by_budget.items()):
            summary.setdefault("walker_legs", {})[f"{k}_{millions}M_steps"] = {
                "seeds": [r["seed"] for r in group],
                "fall_percent": _mean(group, "fall_percent"),
                "worst_decile_return": _mean(group, "worst_decile_return"),
                "mean_return": _mean(group, "mean_return"),
                "uniformity_min_over_mean": float(
                    np.mean([r["uniformity"]["min_over_mean"] for r in group])
                ),
                "uniformity_cv": float(
                    np.mean([r["uniformity"]["coefficient_of_variation"] for r in group])
                ),
                "grid_uniformity": [r.get("grid", {}).get("uniformity") for r in group],
            }
    (RESULTS / "learning.json").write_text(json.dumps(summary, indent=2))
    return summary


def _brief(r: dict) -> dict:
    keys = (
        "seed",
        "env_steps",
        "train_seconds",
        "mean_return",
        "worst_decile_return",
        "task_achievement",
        "fall_percent",
        "mean_forward_speed",
        "uniformity",
    )
    return {k: r[k] for k in keys if k in r} | ({"grid": r["grid"]} if "grid" in r else {})


# configs/walker_legs.yaml's recipe as a family_study variant, its uniform-sampling twin (k = 0)
# and the budget (millions of env steps) their rows are measured at
SHIPPED = ("retarget_stall", "retarget_stall_k0", 2)
BIPED_BASE = "biped_base_heading0.8_std0.1_floor"  # configs/biped_lower.yaml's recipe, base body
# the x0.5 rows: the variant that runs each config's recipe at x0.5 shape ranges
# (variant, its budget in millions of env steps, the runs it warm starts from: variant, millions)
X05 = {
    "biped_lower": ("biped_x0.5_std0.1_floor_warm_widen_kl", 8, (BIPED_BASE, 2)),
    "quadruped": ("quadruped_x0.5_warm_stall_kl", 3, ("quadruped_base_stall", 2)),
}
WALKING = 0.8  # m/s, the x0.5 rows' speed bar: walker_legs' (its target 1.0 m/s, as theirs)


def _study(variant: str, millions: int, seeds=(0, 1, 2)) -> list[dict]:
    runs = []
    for seed in seeds:
        path = RESULTS.parent / "family_study" / f"study_{variant}_s{seed}_{millions}M.json"
        if path.exists():
            runs.append(json.loads(path.read_text()))
    return runs


def _falls_row(variant: str, millions: int, at_most: float, extra: str = "") -> dict:
    runs = _study(variant, millions)
    falls = [r["fall_percent"] for r in runs]
    row = {
        "seeds": [r["seed"] for r in runs],
        "measured": {
            "fall_percent": falls,
            "forward_speed": [r["mean_forward_speed"] for r in runs],
            "worst_decile_over_mean": [
                r["worst_decile_return"] / max(r["mean_return"], 1e-9) for r in runs
            ],
        },
        "command": f"python benchmarks/family_study.py queue {variant} --seeds 0,1,2 "
        f"--steps {millions * 1_000_000}{extra}",
    }
    row["met"] = len(runs) >= 3 and max(falls) <= at_most  # a learning claim needs 3 seeds
    return row


def _humanoid_rows() -> list[dict]:
    """The humanoid's rows: each clip gait's and one-shot skill's latest evaluation per seed
    (benchmarks/humanoid.py `table` -> humanoid/humanoid.json) and each body family's
    (benchmarks/humanoid_families.py, its base-controller rows left out)."""
    rows = []
    path = RESULTS.parent / "humanoid" / "humanoid.json"
    judged = json.loads(path.read_text()) if path.exists() else {}
    for config, r in sorted(judged.items()):
        if config in ("screens", "skills"):
            continue
        seeds = {int(s): x for s, x in r["seeds"].items()}
        targeted = r.get("targeted", True)
        rows.append({
            "target": f"{config}: >= 95 % of 30-s episodes without a fall, body error <= 0.06 m, "
                      "speed within 10 % of the clip's (docs/humanoid.md)" if targeted else
                      f"{config}: a body family's base controller, falls in 30 s and body error "
                      "measured (docs/humanoid.md)",
            "seeds": sorted(seeds),
            "measured": {k: [seeds[s][k] for s in sorted(seeds)]
                         for k in ("fall_percent", "mean_body_error", "speed_ratio", "env_steps")},
            "met": (len(seeds) >= 3 and all(x["met"] for x in seeds.values())) if targeted
                   else None,
            "command": f"paramimic train configs/{config}.yaml --seed N, then "
                       "python benchmarks/humanoid.py eval RUN_DIR",
        })  # fmt: skip
    for config, r in sorted(judged.get("skills", {}).items()):
        latest = {x["train_seed"]: x for x in sorted(r["runs"], key=lambda x: x["env_steps"])}
        t = r["target"]
        rows.append({
            "target": f"{config}: >= {100 * t['share']:.0f} % of 100 tries succeed "
                      f"({t['kind']}) within {t['env_steps'] / 1e6:g}M env steps",
            "seeds": sorted(latest),
            "measured": {k: [latest[s][k] for s in sorted(latest)]
                         for k in ("success_share", "mean_body_error", "env_steps")},
            "met": len(latest) >= 3 and all(x["met"] for x in latest.values()),
            "command": f"paramimic train configs/{config}.yaml --seed N, then "
                       "python benchmarks/humanoid.py skill RUN_DIR",
        })  # fmt: skip
    families: dict[str, dict[int, dict]] = {}
    for path in (RESULTS.parent / "humanoid_families").glob("humanoid_family_*_s*_*k.json"):
        r = json.loads(path.read_text())
        if not r.get("base_controller"):
            seeds = families.setdefault(r["config"], {})
            if r["env_steps"] >= seeds.get(r["train_seed"], {"env_steps": -1})["env_steps"]:
                seeds[r["train_seed"]] = r
    for config, seeds in sorted(families.items()):
        if config.endswith("_uniform"):  # an arm of the k comparison below, not a target
            continue
        if not any("met" in x for x in seeds.values()):  # Fig. 2c, 2d: measured, no target
            rows.append({
                "target": f"{config}: falls in 30 s on 300 held-out bodies, body position "
                          "error, measured (docs/humanoid_families.md)",
                "seeds": sorted(seeds),
                "measured": {
                    "fall_percent": [seeds[s]["report"]["fall_percent"] for s in sorted(seeds)],
                    "mean_body_error": [seeds[s]["report"]["mean_body_error"]
                                        for s in sorted(seeds)],
                    "env_steps": [seeds[s]["env_steps"] for s in sorted(seeds)],
                },
                "met": None,
                "command": f"paramimic train configs/{config}.yaml --seed N, then "
                           "python benchmarks/humanoid_families.py eval RUN_DIR",
            })  # fmt: skip
            continue
        t = next(iter(seeds.values()))["target"]
        rows.append({
            "target": f"{config}: <= {t['fall_percent']:g} % falls in 30 s on 300 held-out "
                      f"bodies, speed within {100 * t['speed_within']:.0f} % of each body's "
                      f"target, within {t['env_steps'] / 1e6:g}M env steps "
                      "(docs/humanoid_families.md)",
            "seeds": sorted(seeds),
            "measured": {
                "fall_percent": [seeds[s]["report"]["fall_percent"] for s in sorted(seeds)],
                "speed_over_target": [seeds[s]["report"]["speed_over_target"]
                                      for s in sorted(seeds)],
                "env_steps": [seeds[s]["env_steps"] for s in sorted(seeds)],
            },
            "met": len(seeds) >= 3 and all(x["met"] for x in seeds.values()),
            "command": f"paramimic train configs/{config}.yaml --seed N, then "
                       "python benchmarks/humanoid_families.py eval RUN_DIR",
        })  # fmt: skip
    return rows + _humanoid_k_rows() + _skill_family_rows()


def _humanoid_k_rows() -> list[dict]:
    """[WL19] Fig. 6 on a humanoid family: adaptive against its uniform arm, per seed
    (benchmarks/humanoid_families.py `table` -> humanoid_families/humanoid_families.json)."""
    path = RESULTS.parent / "humanoid_families" / "humanoid_families.json"
    pairs = json.loads(path.read_text())["pairs"] if path.exists() else []
    rows = []
    for config in sorted({p["config"] for p in pairs}):
        mine = sorted((p for p in pairs if p["config"] == config), key=lambda p: p["seed"])
        rows.append({
            "target": f"{config}: adaptive sampling's worst-decile return >= 1.2x its uniform "
                      "arm's (k = 0) at equal budget, every seed (docs/humanoid_families.md)",
            "seeds": [p["seed"] for p in mine],
            "measured": {"ratio": [p["ratio"] for p in mine],
                         "cv_adaptive": [p["cv"][0] for p in mine],
                         "cv_uniform": [p["cv"][1] for p in mine]},
            "met": len(mine) >= 3 and all(p["met"] for p in mine),
            "command": f"paramimic train configs/{config}.yaml --seed N (and --set "
                       f"curriculum.k=0 --set name={config}_uniform), then python "
                       "benchmarks/humanoid_families.py eval RUN_DIR",
        })  # fmt: skip
    return rows


def _skill_family_rows() -> list[dict]:
    """[L21] skill families trained as service runs: ER within 30M env steps and against
    uniform sampling at equal episodes, per seed (benchmarks/skill_family.py `table`)."""
    path = RESULTS.parent / "skill_family" / "skill_family.json"
    result = json.loads(path.read_text()) if path.exists() else {"runs": [], "pairs": []}
    rows = []
    runs = [r for r in result["runs"] if r["sampling"] == "curriculum"]
    shipped = {r["config"] for r in runs if (ROOT / "configs" / f"{r['config']}.yaml").exists()}
    for config in sorted(shipped):  # screens (--set name=...) are not targets
        mine = sorted((r for r in runs if r["config"] == config), key=lambda r: r["train_seed"])
        pairs = [p for p in result["pairs"] if p["config"] == config]
        rows.append({
            "target": f"{config}: the curriculum reaches refinement and ER >= 0.5 within 30M "
                      "env steps, and >= 1.5x uniform's ER at equal episodes, every seed "
                      "(docs/humanoid_families.md)",
            "seeds": [r["train_seed"] for r in mine],
            "measured": {
                "explored_ratio": [r["explored_ratio"] for r in mine],
                "env_steps": [r["env_steps"] for r in mine],
                "achieved_share": [r["report"].get("achieved_share") for r in mine],
                "ratio_to_uniform": [p["ratio"] for p in pairs],
            },
            "met": len(mine) >= 3 and all(r["met"] for r in mine) and len(pairs) >= 3
            and all(p["met"] for p in pairs),
            "command": f"paramimic train configs/{config}.yaml --seed N (and --set "
                       "curriculum.skill.sampling=uniform), then python "
                       "benchmarks/skill_family.py eval RUN_DIR",
        })  # fmt: skip
    return rows


def targets() -> list[dict]:
    """The family targets' rows from the result files (see the module docstring)."""
    rows = []
    shipped, uniform_twin, millions = SHIPPED
    legs = _falls_row(shipped, millions, 10.0)
    m = legs["measured"]
    legs["met"] = legs["met"] and bool(m["forward_speed"]) and min(m["forward_speed"]) >= 0.8
    legs["met"] = legs["met"] and min(m["worst_decile_over_mean"], default=0) >= 0.5
    rows.append({"target": f"walker_legs (0.7-1.3 per leg) within 5M steps (measured at "
                 f"{millions}M): <= 10 % falls, speed >= 0.8 m/s, worst-decile return >= 0.5x "
                 "the mean"} | legs)  # fmt: skip
    adaptive, uniform = _study(shipped, millions), _study(uniform_twin, millions)
    ratio = None
    if adaptive and uniform:
        wd = lambda runs: float(np.mean([r["worst_decile_return"] for r in runs]))  # noqa: E731
        ratio = wd(adaptive) / wd(uniform)
    rows.append({
        "target": f"adaptive sampling (k = 10) worst-decile return >= 1.2x uniform's (k = 0), "
                  f"equal budget ({millions}M), 3 seeds",
        "seeds": [r["seed"] for r in adaptive], "measured": {"ratio": ratio}, "met": bool(
            ratio and ratio >= 1.2 and len(adaptive) >= 3 and len(uniform) >= 3),
        "command": f"python benchmarks/family_study.py queue {shipped},{uniform_twin} "
                   f"--seeds 0,1,2 --steps {millions * 1_000_000}",
    })  # fmt: skip
    for character, (variant, budget, source) in X05.items():
        # as for walker_legs, a speed keeps the falls honest: a family that stands does not fall
        row = _falls_row(variant, budget, 25.0)
        row["met"] = row["met"] and min(row["measured"]["forward_speed"], default=0) >= WALKING
        target = (f"{character} at x0.5 shape ranges: <= 25 % falls within 10M steps (family "
                  f"measured at {budget}M), walking (speed >= {WALKING} m/s)")  # fmt: skip
        if source:  # the base body's runs first, each family seed from its seed's controller
            before = _falls_row(*source, 100.0)["command"]
            row["command"] = f"{before} && {row['command']}"
            target += (f", warm started from {source[0]} ({source[1]}M, the same seed; "
                       f"{budget + source[1]}M steps in all)")  # fmt: skip
        rows.append({"target": target} | row)
    rows.append(
        {"target": "the base biped_lower walking: <= 10 % falls within 2M steps"}
        | _falls_row(BIPED_BASE, 2, 10.0)
    )
    path = RESULTS.parent / "curriculum" / "curriculum.json"
    er = json.loads(path.read_text()) if path.exists() else {}
    comparison = er.get("comparison", {})
    rows.append({
        "target": "[L21] walker_jump: curriculum ER >= 1.5x uniform's at equal episodes, 3 seeds",
        "seeds": er.get("seeds", []),
        "measured": {"final_ratio": comparison.get("final_ratio"),
                     "area_ratio": comparison.get("area_ratio")},
        "met": bool(comparison.get("target_met")) and len(er.get("seeds", [])) >= 3,
        "command": "python benchmarks/curriculum.py --steps 1500000 --seeds 0,1,2 --jobs 2",
    })  # fmt: skip
    path = RESULTS.parent / "make_train" / "make_train_metrics.jsonl"
    last = json.loads(path.read_text().splitlines()[-1]) if path.exists() else {}
    tail = [json.loads(x) for x in path.read_text().splitlines()[-10:]] if path.exists() else []
    end = float(np.mean([x["fall_percent"] for x in tail])) if tail else None
    rows.append({
        "target": "`make train` (walker_legs, its total_steps, <= 15 min): <= 20 % falls at "
                  "the end (training episodes, mean of the last 10 iterations)",
        "seeds": [0], "measured": {"fall_percent_end": end, "env_steps": last.get("env_steps")},
        "met": end is not None and end <= 20.0,
        "command": "make train  (metrics kept as "
                   "benchmarks/results/make_train/make_train_metrics.jsonl)",
    })  # fmt: skip
    return rows + _humanoid_rows()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("stage", choices=[*STAGES, *RAY_STAGES, "all", "merge", "targets"])
    ap.add_argument("--run", action="store_true", help="`targets`: make missing results first")
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=0, help="seed of a single stage")
    ap.add_argument("--seeds", default="0", help="comma-separated seeds for `all`")
    ap.add_argument("--parallel", type=int, default=2)
    args = ap.parse_args()
    if args.stage == "targets":
        if args.run:
            for row in targets():
                if not row["seeds"] and row["command"].startswith("python"):
                    for command in row["command"].split(" && "):
                        subprocess.call(command.split())
        rows = targets()
        (RESULTS / "targets.json").write_text(json.dumps(rows, indent=1))
        for row in rows:
            verdict = "measured" if row["met"] is None else "met" if row["met"] else "MISSED"
            print(f"{verdict:8} {row['target']}\n         seeds {row['seeds']}: {row['measured']}")
        return
    if args.stage == "all":
        jobs = [(stage, int(seed)) for seed in args.seeds.split(",") for stage in STAGES]

        def sub(job: tuple[str, int]) -> int:
            stage, seed = job
            cmd = [sys.executable, __file__, stage, "--steps", str(args.steps), "--seed", str(seed)]
            return subprocess.call(cmd)

        with ThreadPoolExecutor(args.parallel) as pool:
            codes = list(pool.map(sub, jobs))
        if any(codes):
            raise SystemExit(f"stage exit codes: {dict(zip(jobs, codes, strict=True))}")
    elif args.stage != "merge":
        run_stage(args.stage, args.steps, args.seed)
    print(json.dumps({k: v for k, v in merge().items() if k != "runs"}, indent=2))


if __name__ == "__main__":
    main()
