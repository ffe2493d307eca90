"""ParamEnv steps/s against a raw `mj_step` loop of the same model and frame skip, same run.

Both loops replay the same control sequence from the same state, so the physics work is
identical (same contacts); the difference is ParamEnv's own cost: reference lookup, sensors,
reward, observation, termination and info. Reported for each shipped character, plus
ParamEnv with episode resets (which rebuild the body for a new shape) for a task space with
shape parameters (each reset fits the new body to the ground, [WL19] Eq. 1). Target: ParamEnv
>= 0.85x raw. Writes benchmarks/results/env_speed/env_speed.json.

    python benchmarks/env_speed.py [--steps 3000] [--repeats 5]
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

from paramimic.envs import ParamEnv

warnings.filterwarnings("ignore")
CASES = {
    "walker": ("walker", {"target_velocity": (1.0, 1.0)}),
    "hopper": ("hopper", {"target_velocity": (1.0, 1.0)}),
    "biped_lower": ("biped_lower", {"target_velocity": (1.0, 1.0)}),
    "quadruped": ("quadruped", {"target_velocity": (1.0, 1.0)}),
    "fish": ("fish", {"target_velocity": (0.3, 0.3)}),
    "manta": ("manta", {"target_velocity": (0.3, 0.3)}),
}


def measure(character: str, task: dict, steps: int, repeats: int, seed: int = 0) -> dict:
    env = ParamEnv(character, task, config={"max_episode_seconds": 1e6})
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-0.3, 0.3, (steps, env.action_space.shape[0]))
    env.reset(seed=seed)
    m = env.model
    start = (env.data.qpos.copy(), env.data.qvel.copy(), env.data.ctrl.copy(), env._phase)
    # record the PD targets ParamEnv sends, to replay them in the raw loop
    ctrls = np.empty((steps, m.nu))
    for i in range(steps):
        env.step(actions[i])
        ctrls[i] = env.data.ctrl
    raw_d = mujoco.MjData(m)
    env_t, raw_t = [], []
    for _ in range(repeats):
        env.reset(seed=seed)
        env.data.qpos[:], env.data.qvel[:], env.data.ctrl[:] = start[0], start[1], start[2]
        env._phase = start[3]
        mujoco.mj_forward(m, env.data)
        t = time.perf_counter()
        for i in range(steps):
            env.step(actions[i])
        env_t.append(time.perf_counter() - t)

        mujoco.mj_resetData(m, raw_d)
        raw_d.qpos[:], raw_d.qvel[:] = start[0], start[1]
        t = time.perf_counter()
        for i in range(steps):
            raw_d.ctrl[:] = ctrls[i]
            mujoco.mj_step(m, raw_d, nstep=env.frame_skip)
        raw_t.append(time.perf_counter() - t)
    env_sps = steps / float(np.median(env_t))
    raw_sps = steps / float(np.median(raw_t))
    return {
        "paramenv_steps_per_s": env_sps,
        "raw_mj_step_steps_per_s": raw_sps,
        "ratio": env_sps / raw_sps,
        "frame_skip": env.frame_skip,
        "timestep": m.opt.timestep,
        "steps": steps,
        "repeats": repeats,
    }


def with_resets(steps: int, seed: int = 0) -> dict:
    """Random actions with the usual resets on a shape-varying task space."""
    env = ParamEnv("walker", {"left_leg_length": (0.7, 1.3), "right_leg_length": (0.7, 1.3)})
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    episodes = 0
    t = time.perf_counter()
    for _ in range(steps):
        *_, term, trunc, _ = env.step(rng.uniform(-0.3, 0.3, 6))
        if term or trunc:
            env.reset()
            episodes += 1
    dt = time.perf_counter() - t
    return {
        "steps_per_s": steps / dt,
        "episodes": episodes,
        "mean_episode_steps": steps / max(episodes, 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument(
        "--out", type=Path, default=Path(__file__).parent / "results/env_speed/env_speed.json"
    )
    args = ap.parse_args()
    results = {name: measure(c, t, args.steps, args.repeats) for name, (c, t) in CASES.items()}
    results["walker_legs_with_resets"] = with_resets(args.steps)
    results["machine"] = {
        "python": platform.python_version(),
        "mujoco": mujoco.__version__,
        "processor": platform.processor() or platform.machine(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))
    for name in CASES:
        r = results[name]
        print(
            f"{name:12s} ParamEnv {r['paramenv_steps_per_s']:8.0f} steps/s   raw "
            f"{r['raw_mj_step_steps_per_s']:8.0f} steps/s   ratio {r['ratio']:.3f}"
        )
    r = results["walker_legs_with_resets"]
    print(
        f"walker_legs with resets: {r['steps_per_s']:.0f} steps/s "
        f"({r['mean_episode_steps']:.0f} steps per episode)"
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
