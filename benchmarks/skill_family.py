"""An [L21] skill family trained as a service run (`paramimic train`), judged by [L21]'s own
measures: the explored ratio ER against episodes N (Fig. 8), the curriculum against uniform task
sampling at equal episodes, and the share of tasks the policy achieves.

Train the two arms of a seed (the same config; the baseline only changes the sampling):

    paramimic train configs/humanoid_jump.yaml --seed N --run-dir runs/humanoid_jump_sN
    paramimic train configs/humanoid_jump.yaml --seed N --run-dir runs/humanoid_jump_uniform_sN \
        --set curriculum.skill.sampling=uniform

then judge each run (or one of its checkpoints) and collect the table:

    python benchmarks/skill_family.py eval RUN_DIR|CHECKPOINT [--tasks 100] [--seed 90210]
    python benchmarks/skill_family.py eval configs/humanoid_jump.yaml --base
    python benchmarks/skill_family.py table

`eval` reads the checkpoint's curriculum: ER against N as the run measured it (the share of the
task box whose elite density is at least D, on the curriculum's fixed probe points, after every
batch), its bootstrap stage, phase and elites; then it draws `--tasks` tasks uniformly from the
task box with a seed no training used and performs each with the deterministic policy and
m_a = P_θ(a) (the kNN proxy before P_θ is used; `Method.performer`). A task is achieved when
every measured parameter lands within its σ_task of the goal ([L21] Eq. 8), the clip is
completed and the character does not fall. Writes
benchmarks/results/skill_family/<config>_<sampling>_s<seed>_<k steps>k.json. `eval CONFIG
--base` judges the family's π0 (its `train.init_from`) the same way, every task performed with
m0: the row at 0 steps (<config>_base.json).

`table` takes the latest evaluation of each run, compares each seed's curriculum run with its
uniform run at equal episodes (ER at the shorter run's N, and the mean ER over those N: the
area under the curve, which tells how early a run explored) and writes
benchmarks/results/skill_family/skill_family.json, a Fig. 8 plot per config
(skill_family_<config>.png) and the table of docs/humanoid_families.md (between its
`<!-- skill family -->` markers). Targets (per seed, every seed meeting it): ER >= 0.5 within
30M env steps, and >= 1.5x uniform's ER at equal episodes.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from curriculum import plot  # benchmarks/curriculum.py, beside this script
from humanoid import training_wall_clock  # benchmarks/humanoid.py
from humanoid_families import base_controller  # benchmarks/humanoid_families.py
from tabulate import tabulate

from paramimic.evaluation import evaluate_config
from paramimic.training import checkpoint
from paramimic.training.method import L21, method_for

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "skill_family"
DOCS = ROOT / "docs" / "humanoid_families.md"
MARK = ("<!-- skill family -->", "<!-- /skill family -->")
TARGET_ER, TARGET_STEPS, TARGET_RATIO = 0.5, 30_000_000, 1.5
EVAL_SEED = 90210  # no training run draws its tasks with this seed


def evaluate_run(run: Path, tasks: int, seed: int) -> dict:
    """One run (or checkpoint) by [L21]'s measures: its ER curve, stage and elites, and the
    share of `tasks` uniform tasks it achieves."""
    state, cfg, policy = checkpoint.load_policy(run)
    method = method_for(cfg)
    if not isinstance(method, L21):
        raise SystemExit(f"{run}: not an [L21] skill run (env.clip unset)")
    curriculum = state["curriculum"]
    core = curriculum["core"]
    history = [(int(n), float(er)) for n, er in core["history"]]
    names = list(cfg.task)
    elites = np.asarray(curriculum["elites"]["params"], np.float64).reshape(-1, len(names))
    report = evaluate_config(policy, cfg, tasks, seed, grid_size=1, motions=method.performer(state))
    report.pop("grid", None)
    steps = int(state["progress"]["env_steps"])
    er = history[-1][1] if history else 0.0
    phase = core["phase"] if isinstance(core["phase"], dict) else {"phase": core["phase"]}
    refined = cfg.curriculum.skill.sampling != "curriculum" or bool(phase.get("switches"))
    return {
        "config": cfg.name,
        "sampling": cfg.curriculum.skill.sampling,
        "train_seed": cfg.train.seed,
        "eval_seed": seed,
        "env_steps": steps,
        "iteration": int(state["progress"]["iteration"]),
        "episodes": int(history[-1][0]) if history else 0,
        "training_wall_clock_s": training_wall_clock(run, state["progress"]["iteration"]),
        "stage": core["stage"],
        "phase": phase["phase"],
        "phase_switches": phase.get("switches"),
        "explored_ratio": er,
        "curve": [{"episodes": n, "explored_ratio": e} for n, e in history],
        "elites": {
            "count": len(elites),
            "ranges": {
                n: [float(elites[:, i].min()), float(elites[:, i].max())]
                for i, n in enumerate(names)
            }
            if len(elites)
            else {},
        },  # fmt: skip
        "report": report,
        "target": {"explored_ratio": TARGET_ER, "env_steps": TARGET_STEPS},
        # the curriculum also reached its refinement phase ([L21] §6: a phase switch)
        "met": er >= TARGET_ER and steps - cfg.ppo.num_steps < TARGET_STEPS and refined,
    }


def evaluate_base(config: Path, tasks: int, seed: int) -> dict:
    """The family's starting point judged as a run is: π0 (`train.init_from`) adopted by the
    family's config, no update made, every task performed with m0 (no elites yet): the row at 0
    steps, so that a run's row says what the curriculum added."""
    with tempfile.TemporaryDirectory() as tmp:
        _, cfg, policy = base_controller(config, Path(tmp))
    if not isinstance(method_for(cfg), L21):
        raise SystemExit(f"{config}: not an [L21] skill family (env.clip unset)")
    report = evaluate_config(policy, cfg, tasks, seed, grid_size=1)
    report.pop("grid", None)
    return {
        "config": cfg.name,
        "sampling": "base",
        "train_seed": None,
        "eval_seed": seed,
        "env_steps": 0,
        "iteration": 0,
        "episodes": 0,
        "training_wall_clock_s": 0.0,
        "stage": "π0",
        "phase": "-",
        "phase_switches": 0,
        "explored_ratio": 0.0,
        "curve": [],
        "elites": {"count": 0, "ranges": {}},
        "report": report,
        "target": {"explored_ratio": TARGET_ER, "env_steps": TARGET_STEPS},
        "met": False,
    }


def mean_er(curve: list[dict], n: float) -> float:
    """The mean ER over the first n episodes: the area under the Fig. 8 curve up to n, over n
    (how early a run explored, where ER at n alone only says how far)."""
    ns = np.array([0.0] + [p["episodes"] for p in curve if p["episodes"] < n] + [n])
    ers = np.array([0.0] + [p["explored_ratio"] for p in curve if p["episodes"] < n])
    return float(np.sum(np.diff(ns) * ers) / n) if n > 0 else 0.0


def _er_at(curve: list[dict], n: float) -> float:
    """ER of a run after n episodes (the last batch's measurement at or before n)."""
    ns = [p["episodes"] for p in curve]
    i = int(np.searchsorted(ns, n, side="right")) - 1
    return curve[i]["explored_ratio"] if i >= 0 else 0.0


def pairs(runs: list[dict]) -> list[dict]:
    """Each seed's curriculum run against its uniform run at equal episodes."""
    out = []
    by = {(r["config"], r["sampling"], r["train_seed"]): r for r in runs}
    for (config, sampling, seed), r in sorted(by.items()):
        u = by.get((config, "uniform", seed))
        if sampling != "curriculum" or u is None:
            continue
        n = min(r["episodes"], u["episodes"])
        c_er, u_er = _er_at(r["curve"], n), _er_at(u["curve"], n)
        ratio = c_er / u_er if u_er > 0 else None
        c_mean, u_mean = mean_er(r["curve"], n), mean_er(u["curve"], n)
        out.append({
            "config": config, "seed": seed, "episodes": n,
            "er_curriculum": c_er, "er_uniform": u_er, "ratio": ratio,
            "mean_er_curriculum": c_mean, "mean_er_uniform": u_mean,
            "met": ratio is not None and ratio >= TARGET_RATIO,
        })  # fmt: skip
    return out


def latest_runs() -> list[dict]:
    """Each family's π0 row (`eval --base`) and the latest evaluation (most env steps) of each
    (config, sampling, seed)."""
    latest: dict[tuple, dict] = {}
    for path in sorted(RESULTS.glob("*_s*_*k.json")):
        r = json.loads(path.read_text())
        key = (r["config"], r["sampling"], r["train_seed"])
        if key not in latest or r["env_steps"] > latest[key]["env_steps"]:
            latest[key] = r
    bases = [json.loads(p.read_text()) for p in sorted(RESULTS.glob("*_base.json"))]
    return bases + list(latest.values())


def _table(header, rows) -> str:
    return tabulate(list(rows), headers=list(header), tablefmt="github", disable_numparse=True)


def table() -> dict:
    runs = latest_runs()
    compared = pairs(runs)
    rows = []
    for r in sorted(runs, key=lambda r: (r["config"], r["sampling"] != "base", r["sampling"],
                                         r["train_seed"] or 0)):  # fmt: skip
        rep, base = r["report"], r["sampling"] == "base"
        rows.append([
            r["config"], "π0 (no curriculum)" if base else r["sampling"],
            "any" if base else r["train_seed"], f"{r['env_steps'] / 1e6:.2f}M",
            f"{r['training_wall_clock_s'] / 60:.0f} min", f"{r['episodes']:,}", r["stage"],
            r["phase"], f"{r['explored_ratio']:.3f}", r["elites"]["count"],
            f"{100 * rep.get('achieved_share', 0.0):.0f} %",
            ", ".join(f"{n} {e:.1f}" for n, e in rep.get("task_error_sigmas", {}).items()),
            f"{rep['fall_percent']:.0f} %",
            "" if base else "yes" if r["met"] else "no",
        ])  # fmt: skip
    header = ["config", "sampling", "seed", "env steps", "training wall-clock", "episodes N",
              "stage", "phase", "ER", "elites", "tasks achieved", "error / σ_task", "falls",
              "ER >= 0.5 in 30M"]  # fmt: skip
    body = _table(header, rows)
    if compared:
        body += "\n\nThe curriculum against uniform sampling at equal episodes (per seed):\n\n"
        body += _table(
            ["config", "seed", "episodes N", "ER curriculum", "ER uniform", "ratio", ">= 1.5x",
             "mean ER over N: curriculum", "uniform"],
            [[p["config"], p["seed"], f"{p['episodes']:,}", f"{p['er_curriculum']:.3f}",
              f"{p['er_uniform']:.3f}", "-" if p["ratio"] is None else f"{p['ratio']:.2f}x",
              "yes" if p["met"] else "no", f"{p['mean_er_curriculum']:.3f}",
              f"{p['mean_er_uniform']:.3f}"] for p in compared],
        )  # fmt: skip
    for config in sorted({r["config"] for r in runs}):
        mine = [
            r | {"seed": r["train_seed"]}
            for r in runs
            if r["config"] == config and r["sampling"] != "base"
        ]
        png = RESULTS / f"skill_family_{config}.png"
        plot(mine, png, config)
        body += f"\n\n![ER against episodes N, {config}](data/skill_family/{png.name})"
    targets = {"explored_ratio": TARGET_ER, "env_steps": TARGET_STEPS, "ratio": TARGET_RATIO}
    result = {"runs": runs, "pairs": compared, "targets": targets}
    (RESULTS / "skill_family.json").write_text(json.dumps(result, indent=1))
    text = DOCS.read_text()
    head, rest = text.split(MARK[0], 1)
    _, tail = rest.split(MARK[1], 1)
    DOCS.write_text(f"{head}{MARK[0]}\n{body}\n{MARK[1]}{tail}")
    print(body)
    return result


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("eval", help="judge a run directory or checkpoint")
    e.add_argument("run", type=Path)
    e.add_argument("--tasks", type=int, default=100)
    e.add_argument("--seed", type=int, default=EVAL_SEED)
    e.add_argument("--base", action="store_true", help="RUN is a family config: judge its π0")
    sub.add_parser("table", help="collect the evaluations into the JSON and docs")
    args = p.parse_args()
    if args.cmd == "eval":
        if args.base:
            r = evaluate_base(args.run, args.tasks, args.seed)
            name = f"{r['config']}_base.json"
        else:
            r = evaluate_run(args.run, args.tasks, args.seed)
            name = (
                f"{r['config']}_{r['sampling']}_s{r['train_seed']}_{r['env_steps'] // 1000}k.json"
            )
        RESULTS.mkdir(parents=True, exist_ok=True)
        out = RESULTS / name
        out.write_text(json.dumps(r, indent=1))
        rep = r["report"]
        print(
            f"{r['config']} ({r['sampling']}) seed {r['train_seed']} at {r['env_steps']:,} steps: "
            f"N {r['episodes']:,}, ER {r['explored_ratio']:.3f}, stage {r['stage']}, phase "
            f"{r['phase']}, {r['elites']['count']} elites; tasks achieved "
            f"{100 * rep.get('achieved_share', 0.0):.0f} %, falls {rep['fall_percent']:.0f} %"
        )
        print(f"wrote {out}")
    else:
        table()


if __name__ == "__main__":
    main()
