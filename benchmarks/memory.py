"""Where a rollout actor's memory goes: resident set size after each import and step of its
set-up, in one fresh process (/proc/self/status VmRSS). Writes
benchmarks/results/memory/memory.json.

    python benchmarks/memory.py [--config configs/walker_legs.yaml]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--config", default="configs/walker_legs.yaml")
    args = ap.parse_args()
    steps: dict[str, float] = {"python": rss_mb()}

    def mark(name: str) -> None:
        steps[name] = rss_mb() - sum(steps.values())

    import numpy  # noqa: F401
    import scipy.optimize  # noqa: F401
    import scipy.spatial  # noqa: F401

    mark("numpy and scipy")
    import mujoco  # noqa: F401

    mark("mujoco")
    import ray  # noqa: F401

    mark("ray")
    from paramimic.config import load_config
    from paramimic.envs import env_for
    from paramimic.rl.rollout import RolloutWorker  # noqa: F401

    mark("paramimic (rollout side, no torch)")
    cfg = load_config(ROOT / args.config)
    envs = [env_for(cfg) for _ in range(cfg.actors.num_envs)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
    mark(f"{cfg.actors.num_envs} envs")
    for s in range(200):
        envs[s % len(envs)].reset(seed=100 + s)
    mark("200 resets (the bounded cache of compiled bodies)")
    import torch  # noqa: F401

    mark("torch (the learner only; actors no longer import it)")
    report = {"config": args.config, "rss_mb": steps, "total_mb": rss_mb()}
    out = ROOT / "benchmarks" / "results" / "memory" / "memory.json"
    out.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
