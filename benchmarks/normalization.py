"""[WL19] Table 4 at laptop scale: reward normalization (RN) on and off, at equal budget.

For `biped_lower` and `quadruped` (configs/<character>.yaml: every shape parameter b_g, b_l at
its [WL19] §5.3 range, target speed 1 m/s, adaptive shape sampling), train with RN on and off
for --steps each (serial, the same seed), then evaluate each controller on 300 random shapes
with a 30 s horizon: task achievement (mean cumulative task reward, Eq. 6 share of the reward,
each under its own reward function as in the paper) and fall-down % within 30 s. Also the mean
forward speed. Runs two trainings at a time (2 cores); writes
benchmarks/results/normalization_<character>_<rn|no_rn>_<steps>k_s<seed>.json and the summary
benchmarks/results/normalization.json.

    python benchmarks/normalization.py all [--steps 1000000] [--seed 0]
    python benchmarks/normalization.py biped_lower_rn --steps 200000   # one stage
    python benchmarks/normalization.py merge
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from learning import RESULTS, ROOT, _train_ours  # noqa: E402

CHARACTERS = ("biped_lower", "quadruped")
STAGES = tuple(f"{c}_{rn}" for c in CHARACTERS for rn in ("rn", "no_rn"))
EVAL_SECONDS = 30.0  # fall-down within 30 s ([WL19] §5 Table 4)


def run_stage(stage: str, steps: int, seed: int) -> dict:
    warnings.filterwarnings("ignore")
    normalize = not stage.endswith("_no_rn")
    character = stage.removesuffix("_no_rn" if not normalize else "_rn")
    run_dir = ROOT / "runs" / "bench" / f"normalization_{stage}_s{seed}"
    shutil.rmtree(run_dir, ignore_errors=True)
    report = _train_ours(
        f"configs/{character}.yaml",
        steps,
        {"env.reward.normalize": normalize},
        run_dir,
        seed,
        eval_seconds=EVAL_SECONDS,
    )
    report.update({"stage": stage, "character": character, "normalize": normalize, "seed": seed})
    report["budget_steps"] = steps
    RESULTS.mkdir(parents=True, exist_ok=True)
    name = f"normalization_{stage}_{steps // 1000}k_s{seed}.json"
    (RESULTS / name).write_text(json.dumps(report, indent=2))
    return report


def merge() -> dict:
    table = {}
    for path in sorted(RESULTS.glob("normalization_*_s*.json")):
        r = json.loads(path.read_text())
        budget = r.get("budget_steps") or round(r["env_steps"], -5)
        table[f"{r['stage']}_{budget // 1000}k_s{r['seed']}"] = {
            "character": r["character"],
            "reward_normalization": r["normalize"],
            "seed": r["seed"],
            "env_steps": r["env_steps"],
            "train_seconds": round(r["train_seconds"], 1),
            "episodes": r["episodes"],
            "task_achievement": r["task_achievement"],
            "fall_percent": r["fall_percent"],
            "mean_return": r["mean_return"],
            "mean_forward_speed": r["mean_forward_speed"],
            "mean_length_seconds": r["mean_length_seconds"],
        }
    summary = {"eval_horizon_seconds": EVAL_SECONDS, "runs": table}
    (RESULTS / "normalization.json").write_text(json.dumps(summary, indent=2))
    return summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("stage", choices=[*STAGES, "all", "merge"])
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parallel", type=int, default=2)
    args = ap.parse_args()
    if args.stage == "all":

        def sub(stage: str) -> int:
            cmd = [sys.executable, __file__, stage, "--steps", str(args.steps)]
            return subprocess.call([*cmd, "--seed", str(args.seed)])

        with ThreadPoolExecutor(args.parallel) as pool:
            codes = list(pool.map(sub, STAGES))
        if any(codes):
            raise SystemExit(f"stage exit codes: {dict(zip(STAGES, codes, strict=True))}")
    elif args.stage != "merge":
        run_stage(args.stage, args.steps, args.seed)
    print(json.dumps(merge(), indent=2))


if __name__ == "__main__":
    main()
