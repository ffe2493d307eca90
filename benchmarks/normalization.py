"""[WL19] Table 4 at laptop scale: reward normalization (RN) on and off, at equal budget.

For `biped_lower` and `quadruped` (configs/<character>.yaml: every shape parameter b_g, b_l at
its [WL19] §5.3 range, target speed 1 m/s, adaptive shape sampling), train with RN on and off
for --steps each (serial, the same seed), then evaluate each controller on 300 random shapes
with a 30 s horizon: task achievement (mean cumulative task reward, Eq. 6 share of the reward,
each under its own reward function as in the paper) and fall-down % within 30 s. Also the mean
forward speed. Runs two trainings at a time (2 cores); writes benchmarks/results/normalization/
normalization_<character>_<rn|no_rn>_<steps>k_s<seed>[_x<scale>][_ppo-<preset>].json and the
summary benchmarks/results/normalization/normalization.json.

--shape-scale s < 1 shrinks every shape range toward the base body (lo' = 1 - s(1 - lo),
hi' = 1 + s(hi - 1)): the paper trains for 50-100M transitions, a laptop for ~1M, and at the
full ranges nothing learns to stay up in that budget (measured: 92-100 % falls both ways).

    python benchmarks/normalization.py all [--steps 1000000] [--seed 0] [--shape-scale 1]
    python benchmarks/normalization.py biped_lower_rn --steps 200000   # one stage
    python benchmarks/normalization.py quadruped_rn quadruped_no_rn --shape-scale 0.25
    python benchmarks/normalization.py merge
    python benchmarks/normalization.py open-loop   # why balance comes first (no training)
    python benchmarks/normalization.py biped_lower_rn --shape-scale 0.25 --ppo wl19

--ppo wl19 trains with [WL19] Table 2's PPO step sizes (policy 5e-5, value 1e-4, minibatches of
128) instead of the configs' (2e-4, 1e-3, 512); results get a _ppo-wl19 suffix.

`open-loop` runs the reference motion with zero action (the PD servos track the sinusoidal gait,
no policy) on random bodies at shape scales 0, 0.25, 0.5 and 1 (30 episodes of the config's
horizon each), and on bodies where only one segment varies (scale 0.25, 10 episodes per
segment): fall % and mean episode length, in
benchmarks/results/normalization/normalization_open_loop.json.
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

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "normalization"
EVAL_EPISODES, EVAL_SEED = 300, 2024  # shapes no training run draws

CHARACTERS = ("biped_lower", "quadruped")
STAGES = tuple(f"{c}_{rn}" for c in CHARACTERS for rn in ("rn", "no_rn"))
EVAL_SECONDS = 30.0  # fall-down within 30 s ([WL19] §5 Table 4)
# --ppo presets: the configs' PPO (the [L21] §7 learning rates, n = 512) or [WL19] Table 2's
PPO_PRESETS = {
    "config": {},
    "wl19": {"ppo.policy_lr": 5e-5, "ppo.value_lr": 1e-4, "ppo.minibatch_size": 128},
}


def shape_ranges(character: str, scale: float) -> dict[str, list[float]]:
    """Every shape range of the character shrunk toward 1 by `scale` (the config's
    `shape_scale`, as task ranges: the runs measured before it existed name them so)."""
    from paramimic.characters import registration

    return {k: list(v) for k, v in registration(character).shape_ranges(scale).items()}


def shrunk_shape_ranges(character: str, scale: float) -> dict[str, list[float]]:
    """Config overrides putting the shrunk shape ranges in the task space."""
    return {f"task.{name}": r for name, r in shape_ranges(character, scale).items()}


def _train_and_evaluate(config: str, steps: int, overrides: dict, run_dir: Path, seed: int):
    """A serial run of `config` from scratch, evaluated on EVAL_EPISODES held-out shapes with
    the [WL19] horizon."""
    import torch

    from paramimic.config import load_config
    from paramimic.evaluation import evaluate_config
    from paramimic.training.trainer import train_serial

    cfg = load_config(
        ROOT / config, overrides | {"train.run_dir": str(run_dir), "train.seed": seed}
    )
    torch.manual_seed(seed)
    t0 = time.perf_counter()
    trainer = train_serial(cfg, steps, run_dir)
    seconds = time.perf_counter() - t0
    policy = trainer.learner.policy
    report = evaluate_config(policy, cfg, EVAL_EPISODES, EVAL_SEED, 5, seconds=EVAL_SECONDS)
    return report | {"env_steps": trainer.progress.env_steps, "train_seconds": seconds,
                     "config": config, "overrides": overrides}  # fmt: skip


def run_stage(
    stage: str, steps: int, seed: int, shape_scale: float = 1.0, ppo: str = "config"
) -> dict:
    warnings.filterwarnings("ignore")
    normalize = not stage.endswith("_no_rn")
    character = stage.removesuffix("_no_rn" if not normalize else "_rn")
    suffix = ("" if shape_scale == 1.0 else f"_x{shape_scale:g}") + _ppo_suffix(ppo)
    run_dir = ROOT / "runs" / "bench" / f"normalization_{stage}_s{seed}{suffix}"
    shutil.rmtree(run_dir, ignore_errors=True)
    overrides = {"env.reward.normalize": normalize} | PPO_PRESETS[ppo]
    if shape_scale != 1.0:
        overrides |= shrunk_shape_ranges(character, shape_scale)
    report = _train_and_evaluate(f"configs/{character}.yaml", steps, overrides, run_dir, seed)
    report.update({"stage": stage, "character": character, "normalize": normalize, "seed": seed})
    report.update({"budget_steps": steps, "shape_scale": shape_scale, "ppo": ppo})
    RESULTS.mkdir(parents=True, exist_ok=True)
    name = f"normalization_{stage}_{steps // 1000}k_s{seed}{suffix}.json"
    (RESULTS / name).write_text(json.dumps(report, indent=2))
    return report


def _ppo_suffix(ppo: str) -> str:
    return "" if ppo == "config" else f"_ppo-{ppo}"


def _zero_action_episodes(character: str, task: dict, episodes: int) -> dict:
    import numpy as np

    from paramimic.config import load_config
    from paramimic.envs import make_env

    cfg = load_config(ROOT / "configs" / f"{character}.yaml")
    env = make_env(cfg.character, task, cfg.env)
    zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    lengths, falls = [], 0
    for episode in range(episodes):
        env.reset(seed=episode)
        steps, terminated, truncated = 0, False, False
        while not (terminated or truncated):
            _, _, terminated, truncated, _ = env.step(zero)
            steps += 1
        lengths.append(steps * env.dt)
        falls += bool(terminated)
    return {
        "episodes": episodes,
        "fall_percent": 100.0 * falls / episodes,
        "mean_length_seconds": float(np.mean(lengths)),
    }


def open_loop(scales=(0.0, 0.25, 0.5, 1.0), segment_scale: float = 0.25) -> dict:
    """Zero-action episodes: how often the reference gait alone keeps random bodies up."""
    from paramimic.config import load_config

    out: dict = {"scales": {}, "one_segment": {"shape_scale": segment_scale}}
    for character in CHARACTERS:
        task = load_config(ROOT / "configs" / f"{character}.yaml").task
        goals = {k: v for k, v in task.items() if k not in shape_ranges(character, 1.0)}
        for scale in scales:
            result = _zero_action_episodes(character, goals | shape_ranges(character, scale), 30)
            out["scales"][f"{character}_x{scale:g}"] = result
            print(character, f"x{scale:g}", result, flush=True)
        shape = shape_ranges(character, segment_scale)
        for segment in sorted({name.rsplit("_", 1)[0] for name in shape}):
            one = {k: v if k.rsplit("_", 1)[0] == segment else [1.0, 1.0] for k, v in shape.items()}
            result = _zero_action_episodes(character, goals | one, 10)
            out["one_segment"][f"{character}_{segment}"] = result
            print(character, segment, result, flush=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "normalization_open_loop.json").write_text(json.dumps(out, indent=2))
    return out


def merge() -> dict:
    table = {}
    for path in sorted(RESULTS.glob("normalization_*_s*.json")):
        r = json.loads(path.read_text())
        budget = r.get("budget_steps") or round(r["env_steps"], -5)
        scale = r.get("shape_scale", 1.0)
        ppo = r.get("ppo", "config")
        suffix = ("" if scale == 1.0 else f"_x{scale:g}") + _ppo_suffix(ppo)
        table[f"{r['stage']}_{budget // 1000}k_s{r['seed']}{suffix}"] = {
            "character": r["character"],
            "shape_scale": scale,
            "ppo": ppo,
            "reward_normalization": r["normalize"],
            "seed": r["seed"],
            "env_steps": r["env_steps"],
            "train_seconds": round(r["train_seconds"], 1),
            "episodes": r["episodes"],
            "task_achievement": r["task_achievement"],
            "fall_percent": r["fall_percent"],
            "mean_return": r["mean_return"],
            "mean_forward_speed": r["mean_forward_speed"],
            "mean_length_seconds": r["mean_length_seconds"],
        }
    summary = {"eval_horizon_seconds": EVAL_SECONDS, "runs": table}
    (RESULTS / "normalization.json").write_text(json.dumps(summary, indent=2))
    return summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("stages", nargs="+", choices=[*STAGES, "all", "merge", "open-loop"])
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shape-scale", type=float, default=1.0, help="shrink the shape ranges")
    ap.add_argument("--parallel", type=int, default=2)
    ap.add_argument("--ppo", choices=sorted(PPO_PRESETS), default="config", help="PPO preset")
    args = ap.parse_args()
    if not 0 <= args.shape_scale <= 1:
        ap.error("--shape-scale must be in [0, 1]")
    if "open-loop" in args.stages:
        if len(args.stages) > 1:
            ap.error("open-loop runs alone (no training stages, no merge)")
        open_loop()
        return
    stages = STAGES if "all" in args.stages else [s for s in args.stages if s != "merge"]
    if len(stages) == 1:
        run_stage(stages[0], args.steps, args.seed, args.shape_scale, args.ppo)
    elif stages:

        def sub(stage: str) -> int:
            cmd = [sys.executable, __file__, stage, "--steps", str(args.steps)]
            cmd += ["--seed", str(args.seed), "--shape-scale", str(args.shape_scale)]
            cmd += ["--ppo", args.ppo]
            return subprocess.call(cmd)

        with ThreadPoolExecutor(args.parallel) as pool:
            codes = list(pool.map(sub, stages))
        if any(codes):
            raise SystemExit(f"stage exit codes: {dict(zip(stages, codes, strict=True))}")
    print(json.dumps(merge(), indent=2))


if __name__ == "__main__":
    main()
