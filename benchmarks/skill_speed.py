"""Where a serial [L21] training iteration spends its time (humanoid_jump by default).

Trains a few iterations in-process (`--serial`'s loop) under cProfile and reports training
steps/s, sampling steps/s, and the shares of the iteration spent in the PPO update, in MuJoCo's
`mj_step`, in the rest of the envs, in P_θ and in the curriculum, for each --threads setting of
`train.torch_threads`. Writes benchmarks/results/skill_speed/skill_speed.json.

    python benchmarks/skill_speed.py [--config configs/humanoid_jump.yaml] [--threads 1,2]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import tempfile
import time
import warnings
from pathlib import Path

from paramimic.config import load_config
from paramimic.training.trainer import SerialBackend, Trainer

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent
PARTS = {  # share of the iteration: cumulative time of these functions
    "ppo_update": ("ppo.py", "update"),
    "mj_step": ("~", "<built-in method mujoco._functions.mj_step>"),
    "envs_total": ("skill_env.py", "step"),
    "p_theta_fit": ("parameterization_net.py", "fit"),
    "curriculum_deal": ("skill.py", "next_deal"),
    "curriculum_ingest": ("skill.py", "ingest"),
}


def measure(config: str, threads: int, iterations: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        cfg = load_config(ROOT / config, {"train.run_dir": tmp, "train.torch_threads": threads})
        trainer = Trainer(cfg, Path(tmp))
        backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
        trainer.iteration(backend)  # warm-up
        profile = cProfile.Profile()
        t0, steps = time.perf_counter(), trainer.progress.env_steps
        profile.enable()
        for _ in range(iterations):
            metrics = trainer.iteration(backend)
        profile.disable()
        seconds = time.perf_counter() - t0
        steps = trainer.progress.env_steps - steps
    stats = pstats.Stats(profile).stats
    shares = {}
    for name, (file, function) in PARTS.items():
        total = sum(v[3] for (f, _, fn), v in stats.items() if f.endswith(file) and fn == function)
        shares[name] = total / seconds
    return {
        "torch_threads": threads,
        "iterations": iterations,
        "train_steps_per_s": steps / seconds,
        "sample_steps_per_s": metrics["sample_steps_per_second"],
        "shares_of_iteration": shares,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--config", default="configs/humanoid_jump.yaml")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--iterations", type=int, default=3)
    args = ap.parse_args()
    report = {
        "config": args.config,
        "runs": [measure(args.config, int(t), args.iterations) for t in args.threads.split(",")],
    }
    out = ROOT / "benchmarks" / "results" / "skill_speed" / "skill_speed.json"
    out.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
