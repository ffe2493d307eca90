"""Throughput on the walker and its peers, in one run. Not a timed test.

(a) raw `mj_step` loop of the same model and frame skip, control steps/s (the ceiling);
(b) one rollout actor stepping its envs without a policy (zero actions);
(c) one actor with the policy (batched forward per step);
(d) two actors sampling at once;
(e) end-to-end training (sampling + PPO updates) on Ray, sync and pipelined;
(f) Stable-Baselines3 PPO on the same gymnasium env with 2 envs (SubprocVecEnv), with SB3's
    defaults and with our n_steps / minibatch / epochs;
(g) RLlib PPO on the same gymnasium env (benchmarks/rllib_arm.py in its own venv,
    `make rllib-venv`; skipped with a note when that venv is missing).
(e) and (g) run for every config of --peer-configs (default walker_base, walker_legs and
humanoid_walk, whose resets, shapes and curriculum are included), so the default mode's ratio to
RLlib is measured side by side in one run; beside each, (a) for that config's body at 600 Hz, so
that training's rate is also a ratio to the raw single-core physics at [WL19]'s rate.
Also the peak RSS of an actor and of the learner. Writes
benchmarks/results/throughput/throughput.json
and prints a table.

    pip install -e ".[bench]"; make rllib-venv; python benchmarks/throughput.py [--iterations 6]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import mujoco
import numpy as np
import ray

from paramimic.config import ExperimentConfig, load_config
from paramimic.envs import env_for
from paramimic.rl.ppo import update_dtype
from services.launch.redis_server import EmbeddedRedis
from services.launch.stack import ray_stack
from services.learner.cluster import start_private

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent


def raw_steps_per_s(cfg: ExperimentConfig, steps: int = 4000) -> float:
    """(a) one MjData, the env's PD targets held, mj_step(nstep=frame_skip) per control step."""
    env = env_for(cfg)
    env.reset(seed=0)
    m, d = env.model, env.data
    ctrl = d.ctrl.copy()
    t = time.perf_counter()
    for _ in range(steps):
        d.ctrl[:] = ctrl
        mujoco.mj_step(m, d, nstep=env.frame_skip)
    return steps / (time.perf_counter() - t)


def actor_steps_per_s(cfg, redis_url: str, n_actors: int, use_policy: bool, rounds: int) -> dict:
    """(b)-(d): fragments from n actors at once (tasks from the sampler actor, episodes reported
    to it, as in training), after one warm-up fragment each."""
    cfg = cfg.model_copy(deep=True)
    cfg.actors.num_actors = n_actors
    with (
        tempfile.TemporaryDirectory() as tmp,
        ray_stack(cfg, Path(tmp), redis_url, f"bench-actors-{n_actors}-{use_policy}") as stack,
    ):
        backend = stack.backend
        weights = [ray.put(stack.trainer.learner.weights())]

        def round_trip() -> int:
            refs = [
                a.sample.remote(weights, 0, backend.steps, backend.n_tasks, use_policy)
                for a in backend.actors
            ]
            return sum(f.num_steps for f in ray.get(refs))

        round_trip()
        t = time.perf_counter()
        steps = sum(round_trip() for _ in range(rounds))
        dt = time.perf_counter() - t
        rss = ray.get([a.peak_rss_mb.remote() for a in backend.actors])
    return {"steps_per_s": steps / dt, "actors": n_actors, "peak_rss_mb_per_actor": max(rss)}


def training_steps_per_s(cfg, redis_url: str, mode: str, iterations: int, tag: str = "") -> dict:
    """(e): whole iterations of the trainer on Ray, after one warm-up iteration."""
    cfg = cfg.model_copy(deep=True)
    cfg.actors.mode = mode
    with (
        tempfile.TemporaryDirectory() as tmp,
        ray_stack(
            cfg, Path(tmp), redis_url, f"bench-training-{cfg.character}-{mode}-{tag}"
        ) as stack,
    ):
        trainer, backend = stack.trainer, stack.backend
        trainer.iteration(backend)
        steps0 = trainer.progress.env_steps
        t = time.perf_counter()
        for _ in range(iterations):
            trainer.iteration(backend)
        dt = time.perf_counter() - t
    return {
        "steps_per_s": (trainer.progress.env_steps - steps0) / dt,
        "mode": mode,
        "actors": backend.num_actors,
        "iterations": iterations,
    }


def sb3_steps_per_s(cfg, ours: bool, steps: int) -> dict:
    """(f) SB3 PPO, 2 envs in subprocesses, end-to-end learn() rate."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    import paramimic.envs  # noqa: F401

    torch.set_num_threads(1)
    venv = make_vec_env(
        lambda: gym.make("paramimic/Walker-v0", config=cfg.env.model_dump()),
        n_envs=2,
        vec_env_cls=SubprocVecEnv,
    )
    kwargs: dict = {}
    if ours:
        p = cfg.ppo
        kwargs = {
            "n_steps": p.num_steps // 2,
            "batch_size": p.minibatch_size,
            "n_epochs": p.num_epochs,
        }
    model = PPO("MlpPolicy", venv, device="cpu", seed=0, verbose=0, **kwargs)
    model.learn(total_timesteps=model.n_steps * 2)  # warm-up: one rollout and one update
    t = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False)
    dt = time.perf_counter() - t
    venv.close()
    return {
        "steps_per_s": steps / dt,
        "hyperparameters": "ours" if ours else "sb3 defaults",
        "n_steps_per_env": model.n_steps,
        "batch_size": model.batch_size,
        "n_epochs": model.n_epochs,
    }


def rllib_steps_per_s(config: str, python: Path, iterations: int) -> dict:
    """(g) RLlib in its own venv (its gymnasium pin differs from ours), as a subprocess."""
    if not python.exists():
        return {"skipped": f"{python} missing: run `make rllib-venv`"}
    out = subprocess.run(
        [str(python), str(ROOT / "benchmarks/rllib_arm.py"), "--config", config]
        + ["--iterations", str(iterations)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def peer_rows(path: str, url: str, iterations: int) -> dict:
    """(e) for one config in both modes beside (a) for its body at 600 Hz; where the config's
    update runs in bfloat16, its default mode again with a float32 update, to show what the
    number format is worth."""
    pc = load_config(ROOT / path, {"actors.num_actors": 2})
    default = pc.actors.mode
    at600 = load_config(ROOT / path, {"env.physics_hz": 600, "env.frame_skip": None})
    rows: dict = {"raw_mj_step_600hz": {"steps_per_s": raw_steps_per_s(at600)}}
    for mode in ("sync", "pipelined"):
        rows[f"ours_{mode}"] = training_steps_per_s(pc, url, mode, iterations, Path(path).stem)
    rows["update_dtype"] = str(update_dtype(pc.ppo.update_precision)).removeprefix("torch.")
    if rows["update_dtype"] != "float32":
        f32 = load_config(ROOT / path, {"actors.num_actors": 2, "ppo.update_precision": "float32"})
        rows[f"ours_{default}_float32_update"] = training_steps_per_s(
            f32, url, default, iterations, Path(path).stem
        )
    return rows | {"default_mode": default, "measured": time.strftime("%Y-%m-%d %H:%M")}


def peer_ratios(peer: dict, rllib: dict) -> None:
    """RLlib's arm and the targets' ratios, in place."""
    peer["rllib"] = rllib
    ours = peer[f"ours_{peer['default_mode']}"]["steps_per_s"]
    if "steps_per_s" in rllib:
        peer["default_over_rllib (target >= 1.5)"] = ours / rllib["steps_per_s"]
        peer["pipelined_over_rllib"] = peer["ours_pipelined"]["steps_per_s"] / rllib["steps_per_s"]
    peer["default_over_raw_600hz (humanoid target >= 1.35)"] = (
        ours / peer["raw_mj_step_600hz"]["steps_per_s"]
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default="configs/walker_base.yaml")
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--sb3-steps", type=int, default=3 * 8192)
    ap.add_argument(
        "--peer-configs",
        default="configs/walker_base.yaml,configs/walker_legs.yaml,configs/humanoid_walk.yaml",
    )
    ap.add_argument(
        "--peers-only",
        action="store_true",
        help="measure only the --peer-configs rows and merge them into --out's JSON",
    )
    ap.add_argument("--rllib-python", type=Path, default=ROOT / ".venv-rllib/bin/python")
    ap.add_argument("--rllib-iterations", type=int, default=4)
    ap.add_argument(
        "--out", type=Path, default=ROOT / "benchmarks/results/throughput/throughput.json"
    )
    args = ap.parse_args()
    cfg = load_config(ROOT / args.config, {"actors.num_actors": 2})
    rows: dict[str, dict] = {}
    if not args.peers_only:
        rows["a_raw_mj_step"] = {"steps_per_s": raw_steps_per_s(cfg)}
    start_private(num_cpus=os.cpu_count())  # a cluster of its own, as `paramimic train` starts
    try:
        with tempfile.TemporaryDirectory() as tmp, EmbeddedRedis(Path(tmp)) as redis_server:
            url = redis_server.url
            if not args.peers_only:
                rows["b_1_actor_no_policy"] = actor_steps_per_s(cfg, url, 1, False, args.rounds)
                rows["c_1_actor_policy"] = actor_steps_per_s(cfg, url, 1, True, args.rounds)
                rows["d_2_actors_policy"] = actor_steps_per_s(cfg, url, 2, True, args.rounds)
                for mode in ("sync", "pipelined"):
                    rows[f"e_training_{mode}"] = training_steps_per_s(
                        cfg, url, mode, args.iterations
                    )
            peers = {
                path: peer_rows(path, url, args.iterations) for path in args.peer_configs.split(",")
            }
    finally:
        ray.shutdown()
    for path, peer in peers.items():  # our Ray is down: RLlib starts its own
        peer_ratios(peer, rllib_steps_per_s(path, args.rllib_python, args.rllib_iterations))
    if args.peers_only:
        result = json.loads(args.out.read_text()) if args.out.exists() else {"peers": {}}
        result["peers"] |= peers
        args.out.write_text(json.dumps(result, indent=2))
        print_peers(peers)
        print(f"merged {len(peers)} peer row(s) into {args.out}")
        return
    rows["learner_peak_rss_mb"] = {
        "value": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    }
    rows["f_sb3_defaults"] = sb3_steps_per_s(cfg, ours=False, steps=args.sb3_steps)
    rows["f_sb3_our_hyperparameters"] = sb3_steps_per_s(cfg, ours=True, steps=args.sb3_steps)
    a, c = rows["a_raw_mj_step"]["steps_per_s"], rows["c_1_actor_policy"]["steps_per_s"]
    e = max(rows["e_training_sync"]["steps_per_s"], rows["e_training_pipelined"]["steps_per_s"])
    ratios = {
        "c_over_a (target >= 0.85)": c / a,
        "b_over_a": rows["b_1_actor_no_policy"]["steps_per_s"] / a,
        "d_over_c (target >= 1.8)": rows["d_2_actors_policy"]["steps_per_s"] / c,
        "e_best_over_sb3_defaults (target >= 3)": e / rows["f_sb3_defaults"]["steps_per_s"],
        "e_best_over_sb3_our_hyperparameters": e / rows["f_sb3_our_hyperparameters"]["steps_per_s"],
        "pipelined_over_sync": rows["e_training_pipelined"]["steps_per_s"]
        / rows["e_training_sync"]["steps_per_s"],
        "actor_peak_rss_mb (target < 400)": rows["d_2_actors_policy"]["peak_rss_mb_per_actor"],
    }
    result = {
        "config": args.config,
        "cpus": os.cpu_count(),
        "num_envs": cfg.actors.num_envs,
        "ppo_num_steps": cfg.ppo.num_steps,
        "rows": rows,
        "ratios": ratios,
        "peers": peers,
        "numpy": np.__version__,
        "mujoco": mujoco.__version__,
        "ray": ray.__version__,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    for name, r in rows.items():
        value = r.get("steps_per_s", r.get("value"))
        if isinstance(value, int | float):  # rows of other measures print their own way
            unit = "MB" if "rss" in name else "steps/s"
            print(f"{name:30s} {value:10.0f} {unit}")
        else:
            print(f"{name:30s} {r}")
    for name, v in ratios.items():
        print(f"{name:45s} {v:8.2f}")
    print_peers(peers)
    print(f"wrote {args.out}")


def print_peers(peers: dict) -> None:
    for path, peer in peers.items():
        print(path, {k: round(v["steps_per_s"]) for k, v in peer.items()
                     if isinstance(v, dict) and "steps_per_s" in v})  # fmt: skip
        print(path, {k: round(v, 2) for k, v in peer.items() if isinstance(v, float)})


if __name__ == "__main__":
    main()
