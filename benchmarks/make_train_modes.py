"""`make train`'s run in sync and pipelined mode (`actors.mode`), seed by seed.

The config `make train` trains (configs/walker_legs.yaml) with `actors.mode` and `train.seed` set,
run as `paramimic train <cfg> --no-api` (a local Ray and an embedded Redis, as `make train`),
then `paramimic eval` on 300 held-out bodies (seed 2024). Run one at a time on an otherwise idle
machine: two runs side by side time each other. `report` compares the modes run by run: training
wall time, steps/s, training falls (first 25 / last 10 iterations) and the held-out falls, speed
and return.

    python benchmarks/make_train_modes.py run --mode pipelined --seed 1
    python benchmarks/make_train_modes.py report
        # -> benchmarks/results/make_train/make_train_modes.json
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "make_train"
RUNS = ROOT / "runs" / "make_train_modes"
CONFIG = ROOT / "configs" / "walker_legs.yaml"
MODES = ("sync", "pipelined")
EVAL_SEED, EVAL_EPISODES = 2024, 300


def run(mode: str, seed: int, steps: int | None) -> None:
    run_dir = RUNS / f"{mode}_s{seed}"
    cfg = yaml.safe_load(CONFIG.read_text())
    cfg["actors"]["mode"], cfg["train"]["seed"] = mode, seed
    if steps is not None:
        cfg["train"]["total_steps"] = steps
    RUNS.mkdir(parents=True, exist_ok=True)
    cfg_path = RUNS / f"{mode}_s{seed}.yaml"
    cfg_path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    cli = [sys.executable, "-m", "services.cli"]
    resume = ["--resume"] if (run_dir / "checkpoints").exists() else []
    subprocess.run([*cli, "train", str(cfg_path), "--run-dir", str(run_dir), "--no-api", *resume],
                   check=True, cwd=ROOT)  # fmt: skip
    subprocess.run([*cli, "eval", str(run_dir), "--episodes", str(EVAL_EPISODES),
                    "--seed", str(EVAL_SEED), "--out", str(run_dir / "eval.json")],
                   check=True, cwd=ROOT)  # fmt: skip


def _row(run_dir: Path) -> dict:
    rows = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]
    held_out = json.loads((run_dir / "eval.json").read_text())
    return {
        "env_steps": rows[-1]["env_steps"],
        "training_minutes": (rows[-1]["time"] - rows[0]["time"]) / 60,
        "steps_per_second": float(np.mean([r["steps_per_second"] for r in rows])),
        "training_falls_first_25": float(np.mean([r["fall_percent"] for r in rows[:25]])),
        "training_falls_last_10": float(np.mean([r["fall_percent"] for r in rows[-10:]])),
        "held_out_falls": held_out["fall_percent"],
        "held_out_speed": held_out["mean_forward_speed"],
        "held_out_return": held_out["mean_return"],
    }


def report() -> dict:
    out: dict = {"config": str(CONFIG.relative_to(ROOT)), "eval_seed": EVAL_SEED,
                 "eval_episodes": EVAL_EPISODES, "runs": {}}  # fmt: skip
    for mode in MODES:
        for run_dir in sorted(RUNS.glob(f"{mode}_s*")):
            if run_dir.is_dir() and (run_dir / "eval.json").exists():
                out["runs"][run_dir.name] = r = _row(run_dir)
                print(f"{run_dir.name:14s} {r['training_minutes']:5.1f} min "
                      f"{r['steps_per_second']:6.0f} steps/s  training falls "
                      f"{r['training_falls_first_25']:4.1f} -> {r['training_falls_last_10']:4.1f} "
                      f"% held-out falls {r['held_out_falls']:4.1f} % at {r['held_out_speed']:.2f} "
                      f"m/s, return {r['held_out_return']:.1f}")  # fmt: skip
    (RESULTS / "make_train_modes.json").write_text(json.dumps(out, indent=2))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("stage", choices=["run", "report"])
    ap.add_argument("--mode", choices=MODES, default="sync")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, help="train.total_steps (default: the config's, 3M)")
    args = ap.parse_args()
    if args.stage == "run":
        run(args.mode, args.seed, args.steps)
    else:
        report()


if __name__ == "__main__":
    main()
