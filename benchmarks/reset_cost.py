"""What a reset costs, and where the time goes.

For each config, N resets with a new random task (a new body each time, as a training actor
sees them early on): the median and 90th percentile of the whole reset, and of its parts —
building the body F(B̄, b) (spec, compile, indices; `body`), binding it to the env (data,
reference table, reward scales; `bind`) and placing it on the ground ([WL19] Eq. 1; `ground`).
Also env steps/s with resets on one core, small random actions, episodes of ~1 s (early
training), against raw `mj_step` of the base model. Writes
benchmarks/results/reset_cost/reset_cost.json.

    python benchmarks/reset_cost.py [--resets 200] [--configs walker_legs,biped_lower,quadruped]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
import warnings
from pathlib import Path

import mujoco
import numpy as np

from paramimic.config import load_config
from paramimic.envs import ParamEnv
from paramimic.envs.core import compiled_body

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ("walker_legs", "biped_lower", "quadruped")


class TimedEnv(ParamEnv):
    """ParamEnv that records how long each part of a reset took (seconds)."""

    timing: dict[str, float] = {}

    def _load(self, task):
        t = time.perf_counter()
        body = self.body_for(task)
        self.timing["body"] = time.perf_counter() - t
        t = time.perf_counter()
        changed = super()._load(task)  # the body is cached now: this is the binding
        self.timing["bind"] = time.perf_counter() - t
        assert self.character is body
        return changed

    def ground_posture(self, qpos):
        t = time.perf_counter()
        out = super().ground_posture(qpos)
        self.timing["ground"] = time.perf_counter() - t
        return out


def measure(name: str, resets: int) -> dict:
    cfg = load_config(ROOT / "configs" / f"{name}.yaml")
    env = TimedEnv(cfg.character, cfg.task, cfg.env)
    env.reset(seed=0)
    rows = []
    for seed in range(1, resets + 1):
        compiled_body.cache_clear()  # every body new, as with continuous shapes
        env.timing = {}
        t = time.perf_counter()
        env.reset(seed=seed)
        total = time.perf_counter() - t
        rows.append([total, *(env.timing.get(k, 0.0) for k in ("body", "bind", "ground"))])
    ms = 1000 * np.array(rows)
    parts = ("reset", "body", "bind", "ground")
    out = {f"{p}_ms_median": float(np.median(ms[:, i])) for i, p in enumerate(parts)}
    out |= {f"{p}_ms_p90": float(np.percentile(ms[:, i], 90)) for i, p in enumerate(parts)}
    return out | steps_with_resets(cfg)


def steps_with_resets(cfg, steps: int = 3000) -> dict:
    """Env steps/s with resets (episodes of ~1 s) against raw mj_step of the base body."""
    env = ParamEnv(cfg.character, cfg.task, cfg.env.model_copy(update={"max_episode_seconds": 1.0}))
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.3, 0.3, (steps, env.action_space.shape[0]))
    t = time.perf_counter()
    for a in actions:
        *_, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    env_sps = steps / (time.perf_counter() - t)
    base = compiled_body(cfg.character, (), 1.0 / cfg.env.physics_hz)
    d = mujoco.MjData(base.model)
    t = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(base.model, d, nstep=env.frame_skip)
        if not np.isfinite(d.qpos).all():
            mujoco.mj_resetData(base.model, d)
    raw_sps = steps / (time.perf_counter() - t)
    return {"env_steps_per_s_with_resets": env_sps, "raw_steps_per_s": raw_sps,
            "ratio_to_raw": env_sps / raw_sps}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--resets", type=int, default=200)
    ap.add_argument("--configs", default=",".join(CONFIGS))
    ap.add_argument(
        "--out", type=Path, default=ROOT / "benchmarks/results/reset_cost/reset_cost.json"
    )
    args = ap.parse_args()
    report = {name: measure(name, args.resets) for name in args.configs.split(",")}
    report["machine"] = {"processor": platform.processor(), "python": platform.python_version()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
