"""[WL19] Fig. 2's humanoid families: one controller for a family of humanoid bodies, judged on
bodies the training never drew.

A family run (configs/humanoid_fig2a.yaml ... fig2d.yaml, each warm started from its base
controller) is evaluated with the deterministic policy on 300 bodies drawn uniformly from its
task space with a seed no training run uses, 30-s episodes from random phases ([WL19] Table 4
counts falls within 30 s; a fall is a fall contact, the root, chest or neck on the ground), and
on a 7 x 7 grid of its two display dims (the per-shape returns of [WL19] Fig. 6, as a heatmap
PNG). Each body's forward speed is compared with its own target speed, the clip's scaled by
[WL19] Table 1's normalization of its legs: `speed_over_target` is the mean ratio,
`on_target_share` the share of bodies within 15 % of theirs.

| family | falls in 30 s | speed | within (env steps of the family run) |
|---|---|---|---|
| humanoid_fig2a (legs 0.5-2.0 x arms 0.5-1.5) | <= 10 % | mean within 15 % of the target | 40M |
| humanoid_fig2b (left x right leg, ±10 %) | <= 5 % | mean within 15 % of the target | 20M |
| humanoid_fig2c, humanoid_fig2d | measured | measured | |

    python benchmarks/humanoid_families.py eval RUN_DIR|CHECKPOINT [--bodies 300] [--seed 2025]
    python benchmarks/humanoid_families.py eval configs/humanoid_fig2b.yaml --base
    python benchmarks/humanoid_families.py table
    python benchmarks/humanoid_families.py morph humanoid_fig2a [--starts 10]

Fig. 6 on the humanoid: a family's uniform arm is the same config trained with `--set
curriculum.k=0 --set name=<family>_uniform` (same seed, same budget); `table` pairs it with the
adaptive run at equal env steps and compares the worst-decile return (target >= 1.2x) and the
CV of the per-body return.

`--base` judges the family's starting point: its base controller adopted by the family's
config (`train.init_from`, new task inputs ignored at first) before any family training, the
row at 0 env steps that says what the family run added.

`morph` is [WL19] §5.2 and Fig. 1 (top): one body walking while its shape follows a path,
rebuilt every control step (legs 2.0 -> 0.5, arms 1.0 -> 1.5, back to the start), over 6, 12 and
24 s, from `--starts` random phases each; it counts the starts that fall before the path ends.

Writes benchmarks/results/humanoid_families/humanoid_family_<config>_s<seed>_<k steps>k.json and
its heatmap PNG beside it (`morph`: morph_<controller>.json); `table` writes the results section
of docs/humanoid_families.md.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

# benchmarks/humanoid.py, beside this script
from humanoid import judged, seed_verdict, training_wall_clock
from tabulate import tabulate

from paramimic.config import load_config
from paramimic.envs import env_for
from paramimic.evaluation import SPEED_TOLERANCE, deterministic, evaluate_config, morph_episode
from paramimic.training import checkpoint
from paramimic.training.trainer import Trainer
from services.media import write_heatmap

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "humanoid_families"
DOCS = ROOT / "docs" / "humanoid_families.md"
MARK = ("<!-- results -->", "<!-- /results -->")
EVAL_SEED = 2025  # never a training seed
UNIFORM = "_uniform"  # the name suffix of a family's uniform-sampling arm (curriculum.k = 0)
UNIFORM_TARGET = 1.2  # adaptive's worst decile over uniform's at equal budget
# family -> (falls %, |speed over target - 1|, env steps of the family run); None: measured only
TARGETS = {
    "humanoid_fig2a": (10.0, SPEED_TOLERANCE, 40_000_000),
    "humanoid_fig2b": (5.0, SPEED_TOLERANCE, 20_000_000),
}


def base_controller(config: Path, run_dir: Path):
    """(progress, config, policy) of a family config's starting point: the Trainer's warm start
    from `train.init_from`, no update made."""
    cfg = load_config(config)
    if cfg.train.init_from is None:
        raise SystemExit(f"{config}: --base needs a family warm started (train.init_from)")
    trainer = Trainer(cfg, run_dir)
    policy = trainer.learner.policy.eval()
    return {"env_steps": 0, "iteration": 0}, cfg, policy


def evaluate_family(run: Path, bodies: int, seed: int, base: bool = False) -> dict:
    if base:
        with tempfile.TemporaryDirectory() as tmp:
            progress, cfg, policy = base_controller(run, Path(tmp))
        wall = 0.0
    else:
        state, cfg, policy = checkpoint.load_policy(run)
        progress = state["progress"]
        wall = training_wall_clock(run, progress["iteration"])
    if cfg.env.gait is None or not any(hi > lo for lo, hi in cfg.task.values()):
        raise SystemExit(f"{run}: not a humanoid family on a clip gait (env.gait, a task range)")
    report = evaluate_config(policy, cfg, bodies, seed, grid_size=7, seconds=30.0)
    if cfg.env.reward.in_place:
        for key in ("speed_over_target", "on_target_share"):
            report.pop(key, None)
    steps = int(progress["env_steps"])
    out = {
        "config": cfg.name,
        "train_seed": cfg.train.seed,
        "base_controller": base,
        "eval_seed": seed,
        "env_steps": steps,
        "iteration": progress["iteration"],
        "training_wall_clock_s": wall,
        "task": {k: list(v) for k, v in cfg.task.items()},
        "report": report,
    }
    target = TARGETS.get(cfg.name)
    if target is not None:
        falls, speed, budget = target
        checks = {
            "falls": report["fall_percent"] <= falls,
            "speed": abs(report["speed_over_target"] - 1.0) <= speed,
            "budget": steps - cfg.ppo.num_steps < budget,  # the run stops after the iteration
        }
        out |= {"target": {"fall_percent": falls, "speed_within": speed, "env_steps": budget},
                "checks": checks, "met": all(checks.values())}  # fmt: skip
    return out


# [WL19] Fig. 1 (top) on Fig. 2a's bodies: the tall body shrinks to half, its arms grow, it returns
FIG1_PATH = [
    {"leg_length": 2.0, "arm_length": 1.0},
    {"leg_length": 0.5, "arm_length": 1.0},
    {"leg_length": 0.5, "arm_length": 1.5},
    {"leg_length": 2.0, "arm_length": 1.0},
]


def morph(run: Path, starts: int, durations=(6.0, 12.0, 24.0)) -> dict:
    """Falls of one body walking while its shape follows FIG1_PATH ([WL19] §5.2)."""
    state, cfg, policy = checkpoint.load_policy(run)
    cfg.env = cfg.env.for_evaluation(max(durations) + 1.0)
    env = env_for(cfg)
    act = deterministic(policy)
    task = env.task_space.center.copy()
    for i, name in enumerate(env.task_space.names):
        task[i] = FIG1_PATH[0].get(name, 1.0)
    rows = []
    for seconds in durations:
        episodes = [morph_episode(act, env, task, FIG1_PATH, seconds, s) for s in range(starts)]
        rows.append({
            "seconds": seconds,
            "starts": starts,
            "falls": sum(e["fell"] for e in episodes),
            "mean_speed": float(np.mean([e["distance"] / e["seconds"] for e in episodes])),
            "episodes": episodes,
        })  # fmt: skip
        print(f"{seconds:.0f} s: {rows[-1]['falls']} of {starts} starts fell")
    return {
        "controller": str(run),
        "config": cfg.name,
        "train_seed": cfg.train.seed,
        "env_steps": int(state["progress"]["env_steps"]),
        "path": FIG1_PATH,
        "rows": rows,
    }


def _rows() -> dict[str, list[dict]]:
    rows: dict[str, list[dict]] = {}
    for path in sorted(RESULTS.glob("humanoid_family_*k.json")):
        r = json.loads(path.read_text())
        rows.setdefault(r["config"], []).append(r)
    return rows


def _speed_cells(rep: dict) -> tuple[str, str]:
    """The speed over the body's target and the share within 15 % (an in-place family has
    neither)."""
    if "speed_over_target" not in rep:
        return "in place", "in place"
    return f"{rep['speed_over_target']:.2f}x", f"{100 * rep['on_target_share']:.0f} %"


def table() -> str:
    header = ["family", "seed", "env steps", "training wall-clock", "bodies", "falls in 30 s",
              "speed / target", "within 15 %", "body error (m)", "worst decile / mean",
              "CV of the per-body return", "target met"]  # fmt: skip
    lines, verdicts = [], []
    for config, runs in sorted(_rows().items()):
        for r in sorted(runs, key=lambda r: (r["train_seed"], r["env_steps"])):
            rep = r["report"]
            met = {True: "yes", False: "no", None: "measured"}[r.get("met")]
            base = r.get("base_controller")
            lines.append([
                config, "any" if base else r["train_seed"],
                "0 (the base controller)" if base else f"{r['env_steps'] / 1e6:.2f}M",
                f"{r.get('training_wall_clock_s', 0) / 60:.0f} min", rep["episodes"],
                f"{rep['fall_percent']:.1f} %", *_speed_cells(rep), f"{rep['mean_body_error']:.3f}",
                f"{rep['worst_decile_return'] / rep['mean_return']:.2f}",
                f"{rep['uniformity']['coefficient_of_variation']:.3f}",
                "" if base else met,
            ])  # fmt: skip
        latest = {}
        for r in runs:
            if r.get("base_controller"):
                continue
            if r["env_steps"] >= latest.get(r["train_seed"], {"env_steps": -1})["env_steps"]:
                latest[r["train_seed"]] = r
        if config in TARGETS:
            met = [s for s, r in latest.items() if r["met"]]
            verdict = seed_verdict(
                {s: judged(r, r["target"]["env_steps"]) for s, r in latest.items()}
            )
            falls = np.mean([r["report"]["fall_percent"] for r in latest.values()])
            verdicts.append(
                f"- {config}: seeds {sorted(latest)} evaluated, {len(met)} meeting the target; "
                f"the 3-seed target is {verdict} (mean falls {falls:.1f} %)."
            )
    body = tabulate(lines, headers=header, tablefmt="github", disable_numparse=True)
    body += "\n\n" + ("\n".join(verdicts) if verdicts else "No family has a judged row yet.")
    pairs = k_pairs(_rows())
    body += k_comparison(pairs)
    summary = {"pairs": pairs, "uniform_target": UNIFORM_TARGET}
    (RESULTS / "humanoid_families.json").write_text(json.dumps(summary, indent=1))
    text = DOCS.read_text()
    start, end = text.index(MARK[0]) + len(MARK[0]), text.index(MARK[1])
    DOCS.write_text(text[:start] + "\n" + body + "\n" + text[end:])
    return body


def k_pairs(rows: dict[str, list[dict]]) -> list[dict]:
    """[WL19] Fig. 6 on a humanoid family: its adaptive sampling (the config's k) against its
    uniform arm (`--set curriculum.k=0 --set name=<family>_uniform`), the same seed at the same
    env steps (within 2 %). Target: the worst-decile return >= UNIFORM_TARGET x uniform's.
    `ceiling`: the ratio adaptive sampling would reach with every body at its mean return (its
    worst decile can not exceed its mean), the most V̄ sampling could lift its worst decile to."""
    out = []
    for config, runs in sorted(rows.items()):
        uniform = rows.get(config + UNIFORM)
        for r in runs if uniform else []:
            same = [u for u in uniform if u["train_seed"] == r["train_seed"]
                    and abs(u["env_steps"] - r["env_steps"]) <= 0.02 * r["env_steps"]]  # fmt: skip
            if r.get("base_controller") or not same:
                continue
            a, u = r["report"], same[0]["report"]
            ratio = a["worst_decile_return"] / u["worst_decile_return"]
            out.append({
                "config": config, "seed": r["train_seed"], "env_steps": r["env_steps"],
                "worst_decile": [a["worst_decile_return"], u["worst_decile_return"]],
                "cv": [a["uniformity"]["coefficient_of_variation"],
                       u["uniformity"]["coefficient_of_variation"]],
                "fall_percent": [a["fall_percent"], u["fall_percent"]],
                "ratio": ratio, "met": ratio >= UNIFORM_TARGET,
                "ceiling": a["mean_return"] / u["worst_decile_return"],
            })  # fmt: skip
    return out


def k_comparison(pairs: list[dict]) -> str:
    """The pairs of `k_pairs` as a table (empty without any)."""
    lines = [
        [p["config"], p["seed"], f"{p['env_steps'] / 1e6:.2f}M", f"{p['worst_decile'][0]:.1f}",
         f"{p['worst_decile'][1]:.1f}", f"{p['ratio']:.2f}x", f"{p['ceiling']:.2f}x",
         f"{p['cv'][0]:.3f}",
         f"{p['cv'][1]:.3f}", f"{p['fall_percent'][0]:.1f} % / {p['fall_percent'][1]:.1f} %",
         "yes" if p["met"] else "no"]
        for p in pairs
    ]  # fmt: skip
    if not lines:
        return ""
    header = ["family", "seed", "env steps", "worst decile (adaptive)", "worst decile (uniform)",
              "ratio", "ceiling (every body at the mean)", "CV (adaptive)", "CV (uniform)",
              "falls (adaptive / uniform)", f">= {UNIFORM_TARGET}x"]  # fmt: skip
    table = tabulate(lines, headers=header, tablefmt="github", disable_numparse=True)
    return "\n\nAdaptive sampling against uniform at equal budget ([WL19] Fig. 6):\n\n" + table


def main() -> None:
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("eval")
    e.add_argument("run", type=Path)
    e.add_argument("--bodies", type=int, default=300)
    e.add_argument("--seed", type=int, default=EVAL_SEED)
    e.add_argument("--base", action="store_true", help="RUN is a family config: judge its start")
    sub.add_parser("table")
    m = sub.add_parser("morph")
    m.add_argument("run", type=Path, help="run, checkpoint or shipped controller of Fig. 2a")
    m.add_argument("--starts", type=int, default=10)
    args = ap.parse_args()
    if args.cmd == "table":
        print(table())
        return
    if args.cmd == "morph":
        r = morph(args.run, args.starts)
        path = RESULTS / f"morph_{args.run.name.removesuffix('.pt')}.json"
        path.write_text(json.dumps(r, indent=2))
        print(f"wrote {path}")
        return
    r = evaluate_family(args.run, args.bodies, args.seed, args.base)
    RESULTS.mkdir(parents=True, exist_ok=True)
    seed = "base" if args.base else f"s{r['train_seed']}"
    stem = f"humanoid_family_{r['config']}_{seed}_{r['env_steps'] // 1000}k"
    (RESULTS / f"{stem}.json").write_text(json.dumps(r, indent=2))
    grid = r["report"].get("grid")
    if grid is not None:
        title = f"{r['config']} seed {r['train_seed']}, {r['env_steps'] / 1e6:.1f}M steps"
        write_heatmap(grid, RESULTS / f"{stem}.png", title)
    rep = r["report"]
    speed, within = _speed_cells(rep)
    speed = "in place" if speed == "in place" else f"speed {speed} its target, {within} within 15 %"
    print(
        f"{r['config']} seed {r['train_seed']} at {r['env_steps']:,} steps: falls "
        f"{rep['fall_percent']:.1f} %, {speed}, body error {rep['mean_body_error']:.3f} m; "
        f"met: {r.get('met', 'measured')}"
    )
    print(f"wrote {RESULTS / stem}.json")


if __name__ == "__main__":
    main()
