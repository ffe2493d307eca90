"""RLlib PPO on our gymnasium env: the peer arm of benchmarks/throughput.py. Not a timed test.

RLlib wants its own gymnasium pin, so this runs in its own venv (`make rllib-venv` builds
`.venv-rllib` with `ray[rllib]` and torch==2.13.0, and this repo installed without deps);
throughput.py calls it as a subprocess between its own arms, so the ratio comes from one run
of the machine. RLlib's new API stack: 2 env runners x 8 envs (like our 2 actors x 16 envs,
one CPU each), one local learner, the config's PPO batch, minibatch, epochs, network (ReLU, as
ours), γ, λ and policy learning rate.

    .venv-rllib/bin/python benchmarks/rllib_arm.py --config configs/walker_legs.yaml --iterations 4

The env is the character's gymnasium id (`paramimic/Walker-v0`; a clip gait's own id, such as
`paramimic/HumanoidWalkGait-v0`) made with the config's task and env sections, shapes drawn
uniformly (RLlib has no curriculum; ours runs its own).
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings

warnings.filterwarnings("ignore")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default="configs/walker_base.yaml")
    ap.add_argument("--iterations", type=int, default=4)
    ap.add_argument("--batch", type=int, help="default: the config's ppo.num_steps")
    ap.add_argument("--minibatch", type=int, help="default: the config's ppo.minibatch_size")
    ap.add_argument("--epochs", type=int, help="default: the config's ppo.num_epochs")
    args = ap.parse_args()

    import ray
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.tune.registry import register_env

    from paramimic.config import load_config
    from paramimic.envs import registered_envs

    cfg = load_config(args.config)
    p = cfg.ppo
    args.batch = args.batch or p.num_steps
    args.minibatch = args.minibatch or p.minibatch_size
    args.epochs = args.epochs or p.num_epochs
    # the character's plain (gait) id, or the clip gait's; the config's task and env replace
    # the id's own
    ids = [k for k, v in registered_envs().items() if v["character"] == cfg.character]
    gait = [k for k in ids if registered_envs()[k].get("config", {}).get("gait") == cfg.env.gait]
    env_id = (gait or ids)[0]
    task, env_config = cfg.task, cfg.env.model_dump()

    def make(_ctx):
        import gymnasium as gym

        import paramimic.envs  # noqa: F401  (registers the ids in the env runner)

        return gym.make(env_id, task=task, config=env_config)

    ray.init(
        address="local",  # a cluster of its own, never the one Ray's temp dir names
        num_cpus=os.cpu_count(),
        include_dashboard=False,
        _node_ip_address="127.0.0.1",
        log_to_driver=False,
    )
    register_env("paramimic_bench", make)
    config = (
        PPOConfig()
        .environment("paramimic_bench")
        .env_runners(num_env_runners=2, num_envs_per_env_runner=8, num_cpus_per_env_runner=1)
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=args.batch,
            minibatch_size=args.minibatch,
            num_epochs=args.epochs,
            gamma=p.gamma,
            lambda_=p.gae_lambda,
            lr=p.policy_lr,
        )
        .rl_module(
            model_config=DefaultModelConfig(
                fcnet_hiddens=list(p.hidden_sizes), fcnet_activation="relu", vf_share_layers=False
            )
        )
    )
    algo = config.build_algo()
    try:
        algo.train()  # warm-up: env runners up, first batch and update
        steps = []
        t = time.perf_counter()
        for _ in range(args.iterations):
            r = algo.train()
            steps.append(r["env_runners"]["num_env_steps_sampled"])
        dt = time.perf_counter() - t
    finally:
        algo.stop()
        ray.shutdown()
    print(
        json.dumps(
            {
                "steps_per_s": sum(steps) / dt,
                "iterations": args.iterations,
                "config": args.config,
                "env": env_id,
                "physics_hz": cfg.env.physics_hz,
                "env_runners": 2,
                "envs_per_runner": 8,
                "batch": args.batch,
                "minibatch": args.minibatch,
                "epochs": args.epochs,
                "hidden_sizes": list(p.hidden_sizes),
                "ray": ray.__version__,
            }
        )
    )


if __name__ == "__main__":
    main()
