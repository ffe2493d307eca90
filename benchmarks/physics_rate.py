"""What physics rate the characters need: speed, fidelity and stability at 600 / 300 / 210 / 150 Hz.

Control stays at 30 Hz ([WL19] Table 2); only `env.physics_hz` (the MuJoCo time step, with
`implicitfast` and the stable PD servos) changes. Stages:

- `speed`: raw control steps/s of the base body (`mj_step(nstep=physics_hz/30)`), one core.
- `fidelity`: the same PD-target sequence (the character's reference motion, open loop: the
  gait for the [WL19] characters, the walk clip for the humanoid) from the same initial state for
  10 s at each rate against 600 Hz: RMS of the COM height difference over the first 1 s and over
  10 s, the share of (control step, foot) whose ground contact differs, and the RMS joint-angle
  difference at 1 s.
- `divergence`: random bodies at the corners of their shape ranges (every shape parameter at its
  low or high end) under uniform random actions for 2 s each: the share of episodes that
  diverge (NaN, exploding velocities or MuJoCo's own reset: the env's `diverged`).
- `stable_pd`: `fidelity` and `divergence` again with the servos as [WL19] Eq. 3's stable PD
  (`env.stable_pd`), fidelity still against the plain servos at 600 Hz.
- `learning`: walker_base (or --config) trained for the same wall-clock budget at each rate
  (--seeds), evaluated on 300 episodes at the rate it trained at; run one (rate, seed) per
  process, two at a time: `python benchmarks/physics_rate.py learning --rate 300 --seed 0`.

Writes benchmarks/results/physics_rate/physics_rate.json (and
physics_rate_learning_<cfg>_<hz>_s<seed>.json).

    python benchmarks/physics_rate.py speed fidelity divergence stable_pd [--bodies 300]
    python benchmarks/physics_rate.py learning --rate 300 --seed 0 [--budget 300]
    python benchmarks/physics_rate.py merge
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

from paramimic.characters import get_character
from paramimic.envs import ParamEnv, SkillEnv
from paramimic.envs.skill_motion import at

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "physics_rate"
RATES = (600, 300, 210, 150)  # 200 Hz is no multiple of the 30 Hz control: 210 (7 substeps)
CHARACTERS = ("walker", "biped_lower", "quadruped", "humanoid")
CONTROL_HZ = 30


def _env(name: str, hz: int, task: dict | None = None, **config):
    config = {"physics_hz": hz, **config}
    if name == "humanoid":
        return SkillEnv(name, task or {}, {"clip": "humanoid_walk", **config})
    return ParamEnv(name, task or {"target_velocity": (1.0, 1.0)}, config)


def speed(rounds: int = 3, steps: int = 600) -> dict:
    out = {}
    for name in CHARACTERS:
        for hz in RATES:
            env = _env(name, hz)
            env.reset(seed=0)
            m, d = env.model, mujoco.MjData(env.model)
            best = 0.0
            for _ in range(rounds):
                mujoco.mj_resetData(m, d)
                d.qpos[:] = env.data.qpos
                t = time.perf_counter()
                for _ in range(steps):
                    mujoco.mj_step(m, d, nstep=env.frame_skip)
                best = max(best, steps / (time.perf_counter() - t))
            out.setdefault(name, {})[str(hz)] = {"control_steps_per_s": best}
    return out


def _open_loop(name: str, hz: int, seconds: float = 10.0, stable_pd: bool = False) -> dict:
    """COM height [T], foot contacts [T, F] and joint angles [T, J] under the reference
    motion's PD targets, from the reference's first pose on the base body."""
    env = _env(name, hz, init_noise=0.0, max_episode_seconds=1e6, stable_pd=stable_pd)
    env.reset(seed=0, options={"task": env.task_space.center})
    c, m, d = env.character, env.model, env.data
    steps = int(round(seconds * CONTROL_HZ))
    if isinstance(env, SkillEnv):
        targets = [at(env._q0, min(k + 1.0, len(env._q0) - 1.0))[c.qpos_idx]
                   for k in range(steps)]  # fmt: skip
    else:
        phase, dphase = env._phase, env.dt / env.motion.period
        targets = [env.motion.pose(phase + (k + 1) * dphase) for k in range(steps)]
    feet = [m.body(f).id for f in env.definition.feet]
    floor = m.geom("floor").id
    com, contact, joints = [], [], []
    for k in range(steps):
        d.ctrl[:] = targets[k]
        mujoco.mj_step(m, d, nstep=env.frame_skip)
        com.append(float(d.subtree_com[c.root_body_id, 2]))
        touching = set()
        for i in range(d.ncon):
            g1, g2 = d.contact.geom1[i], d.contact.geom2[i]
            if floor in (g1, g2):
                touching.add(int(m.geom_bodyid[g2 if g1 == floor else g1]))
        contact.append([f in touching for f in feet])
        joints.append(d.qpos[c.qpos_idx].copy())
    return {"com": np.array(com), "contact": np.array(contact), "joints": np.array(joints)}


def fidelity(stable_pd: bool = False) -> dict:
    """Against the plain servos at 600 Hz, with plain or stable PD servos at every rate."""
    out = {}
    one = CONTROL_HZ  # control steps in 1 s
    for name in CHARACTERS:
        ref = _open_loop(name, 600)
        for hz in RATES:
            run = ref if hz == 600 and not stable_pd else _open_loop(name, hz, stable_pd=stable_pd)
            dz = run["com"] - ref["com"]
            dq = run["joints"][one - 1] - ref["joints"][one - 1]
            out.setdefault(name, {})[str(hz)] = {
                "com_height_rms_1s_m": float(np.sqrt(np.mean(dz[:one] ** 2))),
                "com_height_rms_10s_m": float(np.sqrt(np.mean(dz**2))),
                "contact_mismatch_share": float(np.mean(run["contact"] != ref["contact"])),
                "joint_rms_at_1s_rad": float(np.sqrt(np.mean(dq**2))),
            }
    return out


def divergence(bodies: int, stable_pd: bool = False) -> dict:
    out = {}
    for name in CHARACTERS:
        params = get_character(name).shape_params
        task = {p.name: (p.low, p.high) for p in params}
        for hz in RATES:
            env = _env(name, hz, task, max_episode_seconds=2.0, stable_pd=stable_pd)
            rng = np.random.default_rng(0)
            diverged = 0
            for b in range(bodies):
                corner = {p.name: (p.low if rng.random() < 0.5 else p.high) for p in params}
                env.reset(seed=b, options={"task": corner})
                done = False
                while not done:
                    a = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
                    _, _, term, trunc, info = env.step(a)
                    done = term or trunc
                diverged += bool(info["diverged"])
            out.setdefault(name, {})[str(hz)] = {
                "bodies": bodies,
                "diverged_share": diverged / bodies,
            }
    return out


def learning(config: str, hz: int, seed: int, budget: float) -> dict:
    """Train `config` at `hz` for `budget` wall-clock seconds (serial, one core), evaluate."""
    import torch

    from paramimic.config import load_config
    from paramimic.evaluation import evaluate_config
    from paramimic.training.trainer import SerialBackend, Trainer

    run_dir = ROOT / "runs" / "bench" / f"physics_{Path(config).stem}_{hz}_s{seed}"
    overrides = {"env.physics_hz": hz, "train.run_dir": str(run_dir), "train.seed": seed}
    cfg = load_config(ROOT / config, overrides)
    torch.manual_seed(seed)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "checkpoints").mkdir(exist_ok=True)
    trainer = Trainer(cfg, run_dir)
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    t0 = time.perf_counter()
    trainer.train(backend, 10**9, should_stop=lambda: time.perf_counter() - t0 > budget)
    seconds = time.perf_counter() - t0
    report = evaluate_config(trainer.learner.policy, cfg, 300, 12345, 5)
    report |= {"physics_hz": hz, "seed": seed, "config": config, "budget_seconds": budget,
               "train_seconds": seconds, "env_steps": trainer.progress.env_steps}  # fmt: skip
    path = RESULTS / f"physics_rate_learning_{Path(config).stem}_{hz}_s{seed}.json"
    path.write_text(json.dumps(report, indent=2))
    return report


def merge_learning() -> dict:
    runs: dict[str, dict[str, list[dict]]] = {}
    for path in sorted(RESULTS.glob("physics_rate_learning_*_s*.json")):
        r = json.loads(path.read_text())
        runs.setdefault(Path(r["config"]).stem, {}).setdefault(str(r["physics_hz"]), []).append(r)
    out = {}
    for cfg, by_rate in runs.items():
        for hz, rs in by_rate.items():
            out.setdefault(cfg, {})[hz] = {
                "seeds": [r["seed"] for r in rs],
                "budget_seconds": rs[0]["budget_seconds"],
                "env_steps": [r["env_steps"] for r in rs],
                "mean_return": [round(r["mean_return"], 1) for r in rs],
                "fall_percent": [round(r["fall_percent"], 1) for r in rs],
            }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("stages", nargs="+", choices=["speed", "fidelity", "divergence", "stable_pd",
                                                  "learning", "merge"])  # fmt: skip
    ap.add_argument("--bodies", type=int, default=300)
    ap.add_argument("--config", default="configs/walker_base.yaml")
    ap.add_argument("--rate", type=int, default=600)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--budget", type=float, default=300.0, help="wall-clock seconds of training")
    args = ap.parse_args()
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / "physics_rate.json"
    report = json.loads(path.read_text()) if path.exists() else {}
    for stage in args.stages:
        if stage == "speed":
            report["speed"] = speed()
        elif stage == "fidelity":
            report["fidelity"] = fidelity()
        elif stage == "divergence":
            report["divergence"] = divergence(args.bodies)
        elif stage == "stable_pd":
            report["stable_pd"] = {
                "fidelity": fidelity(stable_pd=True),
                "divergence": divergence(args.bodies, stable_pd=True),
            }
        elif stage == "learning":
            learning(args.config, args.rate, args.seed, args.budget)
        report["learning"] = merge_learning()
    report["machine"] = {"processor": platform.processor(), "python": platform.python_version()}
    path.write_text(json.dumps(report, indent=2))
    print(json.dumps({k: v for k, v in report.items() if k != "machine"}, indent=2))


if __name__ == "__main__":
    main()
