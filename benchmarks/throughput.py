"""End-to-end throughput, side by side in one run ([DESIGN] "How we know it works").

Env steps/s of: raw MuJoCo stepping of the same model (the ceiling, one core), the serial
trainer (rollouts + PPO update in one process), and the Ray trainer with 1 actor and with N
actors, each in sync and pipelined mode. Every trainer row runs the same config for the same
number of iterations after one warm-up iteration (actor start-up excluded).
Writes benchmarks/results/throughput.json.

    python benchmarks/throughput.py [--config configs/walker_base.yaml] [--iterations 8]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
import warnings
from pathlib import Path

import mujoco
import ray

from paramimic.config import load_config
from paramimic.envs import make_env
from services.learner.ray_backend import RayBackend
from services.learner.trainer import SerialBackend, Trainer

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent


def raw_steps_per_s(cfg, steps: int = 3000) -> float:
    env = make_env(cfg.character, cfg.task, cfg.env)
    env.reset(seed=0)
    m, d = env.model, env.data
    ctrl = d.ctrl.copy()
    t = time.perf_counter()
    for _ in range(steps):
        d.ctrl[:] = ctrl
        mujoco.mj_step(m, d, nstep=env.frame_skip)
    return steps / (time.perf_counter() - t)


def trainer_steps_per_s(cfg, backend_kind: str, iterations: int, **actors) -> dict:
    cfg = cfg.model_copy(deep=True)
    for k, v in actors.items():
        setattr(cfg.actors, k, v)
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(cfg, Path(tmp))
        if backend_kind == "serial":
            backend = SerialBackend(
                cfg, trainer.obs_dim, trainer.act_dim, trainer.sampler.next_tasks
            )
        else:
            backend = RayBackend(
                cfg, trainer.obs_dim, trainer.act_dim, trainer.sampler.next_tasks, cfg.ppo.num_steps
            )
        try:
            trainer.iteration(backend)  # warm-up: actor start, first weights
            steps0 = trainer.progress.env_steps
            t = time.perf_counter()
            for _ in range(iterations):
                trainer.iteration(backend)
            dt = time.perf_counter() - t
        finally:
            backend.close()
        return {
            "steps_per_s": (trainer.progress.env_steps - steps0) / dt,
            "iterations": iterations,
            "seconds": dt,
            "actors": getattr(backend, "num_actors", 0),
            **actors,
        }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default="configs/walker_base.yaml")
    ap.add_argument("--iterations", type=int, default=8)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/throughput.json")
    args = ap.parse_args()
    cfg = load_config(ROOT / args.config)
    cpus = os.cpu_count() or 1
    n = max(1, cpus)
    rows = {"raw_mj_step_one_core": {"steps_per_s": raw_steps_per_s(cfg)}}
    rows["serial"] = trainer_steps_per_s(cfg, "serial", args.iterations)
    ray.init(
        num_cpus=cpus, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False
    )
    try:
        for mode in ("sync", "pipelined"):
            rows[f"ray_1_actor_{mode}"] = trainer_steps_per_s(
                cfg, "ray", args.iterations, num_actors=1, mode=mode
            )
            rows[f"ray_{n}_actors_{mode}"] = trainer_steps_per_s(
                cfg, "ray", args.iterations, num_actors=n, mode=mode
            )
    finally:
        ray.shutdown()
    result = {
        "config": args.config,
        "cpus": cpus,
        "num_envs": cfg.actors.num_envs,
        "ppo_num_steps": cfg.ppo.num_steps,
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    for name, r in rows.items():
        print(f"{name:28s} {r['steps_per_s']:8.0f} env steps/s")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
