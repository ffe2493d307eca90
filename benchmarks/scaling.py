"""Actors on one Ray node against actors spread over two nodes, with the same total cores.
Not a timed test.

- one node: a `ray start --head` node with 2 CPUs; both actors on it, beside the learner.
- two nodes: a head with 0 CPUs (the learner's node) and two worker nodes of 1 CPU each, each
  in its own network namespace over a veth pair (loopback if namespaces are not allowed), so
  every fragment crosses from a worker's object store to the learner's.

Both with token authentication, a real Redis and the sampler actor, as in training. Measured:
sampling (the learner's `collect` of a fragment per actor, weights fixed) and end-to-end
training iterations (sampling + PPO update), env steps/s after a warm-up. Target: the two-node
overhead <= 10 %. Writes benchmarks/results/scaling/scaling.json.

    python benchmarks/scaling.py [--config configs/walker_legs.yaml] [--rounds 8]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ray

from paramimic.config import load_config
from services.launch.local_cluster import LocalCluster
from services.launch.redis_server import EmbeddedRedis
from services.launch.stack import ray_stack

ROOT = Path(__file__).resolve().parent.parent


def measure(cfg, address: str, node_ip: str, redis_url: str, rounds: int) -> dict:
    """In a driver process that has the cluster's token in its environment from the start."""
    ray.init(address=address, _node_ip_address=node_ip, log_to_driver=False)
    try:
        with (
            tempfile.TemporaryDirectory() as tmp,
            ray_stack(cfg, Path(tmp), redis_url, f"bench-scaling-{time.time_ns()}") as stack,
        ):
            trainer, backend = stack.trainer, stack.backend
            weights = trainer.learner.weights()
            backend.collect(weights, 0)  # warm-up
            t, steps = time.perf_counter(), 0
            for _ in range(rounds):
                steps += sum(f.num_steps for f in backend.collect(weights, 0))
            sampling = steps / (time.perf_counter() - t)
            trainer.iteration(backend)  # warm-up
            steps0, t = trainer.progress.env_steps, time.perf_counter()
            for _ in range(rounds):
                trainer.iteration(backend)
            training = (trainer.progress.env_steps - steps0) / (time.perf_counter() - t)
            stats = backend.stats()
    finally:
        ray.shutdown()
    return {
        "sampling_steps_per_s": sampling,
        "training_steps_per_s": training,
        "actors": stats["actors"],
        "nodes": stats["nodes"],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/walker_legs.yaml")
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument(
        "--out", default=str(ROOT / "benchmarks" / "results" / "scaling" / "scaling.json")
    )
    p.add_argument("--measure", nargs=3, metavar=("ADDRESS", "NODE_IP", "REDIS_URL"),
                   help=argparse.SUPPRESS)  # fmt: skip
    args = p.parse_args()
    cfg = load_config(ROOT / args.config, {"actors.num_actors": "auto"})
    if args.measure:
        print(json.dumps(measure(cfg, *args.measure, args.rounds)))
        return
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        redis = EmbeddedRedis(Path(tmp) / "redis")
        url = redis.start()
        try:
            for setup, head_cpus, workers in (("one_node", 2, 0), ("two_nodes", 0, 2)):
                cluster = LocalCluster(head_cpus=head_cpus)
                try:
                    cluster.start()
                    for _ in range(workers):
                        cluster.add_worker(cpus=1)
                    child = subprocess.run(
                        [sys.executable, __file__, "--config", args.config, "--rounds",
                         str(args.rounds), "--measure", cluster.address, cluster.head_ip, url],
                        env=cluster.env, capture_output=True, text=True, check=True,
                    )  # fmt: skip
                    results[setup] = json.loads(child.stdout.strip().splitlines()[-1])
                    results[setup]["network_namespaces"] = bool(workers and cluster.use_netns)
                finally:
                    cluster.stop()
                print(setup, results[setup], flush=True)
        finally:
            redis.stop()
    one, two = results["one_node"], results["two_nodes"]
    out = {
        "config": args.config,
        "rounds": args.rounds,
        "results": results,
        "overhead_sampling": 1 - two["sampling_steps_per_s"] / one["sampling_steps_per_s"],
        "overhead_training": 1 - two["training_steps_per_s"] / one["training_steps_per_s"],
        "target": "two-node overhead <= 10 %",
        "command": "python benchmarks/scaling.py " + " ".join(sys.argv[1:]),
    }
    out["target_met"] = max(out["overhead_sampling"], out["overhead_training"]) <= 0.10
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: out[k] for k in ("overhead_sampling", "overhead_training", "target_met")}))


if __name__ == "__main__":
    main()
