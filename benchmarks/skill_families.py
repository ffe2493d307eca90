"""How far each shipped [L21] skill family gets at a laptop budget, beside the paper's.

Each family config (declared task parameters from the measure library, `paramimic clip info`
for a0) trains with the exploration/refinement curriculum for a fixed number of env steps on the
serial backend (the same Trainer, curriculum and P_θ as the service); the row reports the
episodes N it generated, the stage and phase it reached, ER (share of the task box whose elite
density is at least D = 0.8), the elites and how much of each free task range they cover, and
the latest episodes' a' per parameter — next to [L21] Table 1's N and ER for the same skill.

    pip install -e ".[bench]"
    python benchmarks/skill_families.py [--families humanoid_jump,walker_jump_energy]
        [--steps 300000] [--walker-steps 1000000] [--seed 0] [--jobs 2]
    python benchmarks/skill_families.py --table

Writes benchmarks/results/skill_families/skill_families.json; each finished run is kept in
benchmarks/results/skill_families/runs/<family>_s<seed>_<steps>.json and not run again.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
from pathlib import Path

import numpy as np
from tabulate import tabulate

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "skill_families"
RUNS = RESULTS / "runs"

# family -> ([L21] Table 1 skill, its episodes N, its ER); None where the paper has no such row
FAMILIES = {
    "walker_jump_energy": ("Jump", 1.65e6, 0.92),
    "humanoid_jump": ("Jump", 1.65e6, 0.92),
    "humanoid_backflip": ("Backflip", 2.1e6, 0.9),
    "humanoid_cartwheel": ("Cartwheel", 3.5e6, 1.0),
    "humanoid_run": (None, None, None),
}


def _table(header, rows) -> str:
    """A GitHub Markdown table."""
    return tabulate(list(rows), headers=list(header), tablefmt="github", disable_numparse=True)


def one(job: tuple) -> dict:
    family, steps, seed = job
    import yaml

    from benchmarks.curriculum import run
    from paramimic.config import load_config

    out = RUNS / f"{family}_s{seed}_{steps}.json"
    if out.exists():
        return json.loads(out.read_text())
    config = f"configs/{family}.yaml"
    result = run(config, "curriculum", steps, seed, ROOT / "runs" / "skill_families" / out.stem)
    cfg = load_config(ROOT / config)
    last = result["curve"][-1]
    elites = result["elites"]
    spread = {}
    for name, (lo, hi) in cfg.task.items():
        covered = elites["ranges"].get(name)
        if hi > lo:
            spread[name] = None if covered is None else (covered[1] - covered[0]) / (hi - lo)
    row = {
        "family": family,
        "config": config,
        "declared": yaml.safe_load((ROOT / config).read_text())["task"],
        "seed": seed,
        "steps": steps,
        "seconds": result["seconds"],
        "episodes": last["episodes"],
        "stage": last["stage"],
        "phase": last["phase"],
        "explored_ratio": last["explored_ratio"],
        "elites": last["elites"],
        "elite_mean_fitness": last["elite_mean_fitness"],
        "elite_spread": spread,
        "curve": [
            {k: c[k] for k in ("env_steps", "episodes", "explored_ratio", "elites", "stage")}
            for c in result["curve"]
        ],
        "paper": dict(zip(("skill", "episodes", "explored_ratio"), FAMILIES[family], strict=True)),
    }
    RUNS.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(row, indent=1))
    return row


def table(rows: list[dict]) -> str:
    header = ["family", "env steps", "episodes N", "stage / phase", "ER", "elites (mean F)",
              "elites cover (share of each free range)", "[L21] Table 1: N, ER"]  # fmt: skip
    lines = []
    for r in rows:
        cover = ", ".join(
            f"{k} {'–' if v is None else f'{v:.2f}'}" for k, v in r["elite_spread"].items()
        )
        p = r["paper"]
        paper = "no row" if p["skill"] is None else (
            f"{p['skill']}: {p['episodes'] / 1e6:.2f}M, {p['explored_ratio']}"
        )  # fmt: skip
        fit = r["elite_mean_fitness"]
        elites = f"{r['elites']} ({'–' if fit is None else f'{fit:.2f}'})"
        lines.append([r["family"], f"{r['steps'] / 1e6:.2f}M", f"{r['episodes']:,}",
                      f"{r['stage']} / {r['phase']}", f"{r['explored_ratio']:.2f}", elites,
                      cover, paper])  # fmt: skip
    return _table(header, lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--steps", type=int, default=300_000, help="env steps per humanoid family")
    ap.add_argument("--walker-steps", type=int, default=1_000_000, help="env steps (walker)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--table", action="store_true", help="print the table of the saved rows")
    args = ap.parse_args()
    families = [f for f in args.families.split(",") if f]
    unknown = set(families) - set(FAMILIES)
    if unknown:
        ap.error(f"--families: unknown {sorted(unknown)}; one of {list(FAMILIES)}")
    if args.table:
        rows = json.loads((RESULTS / "skill_families.json").read_text())["rows"]
        print(table(rows))
        return
    jobs = [
        (f, args.walker_steps if f.startswith("walker") else args.steps, args.seed)
        for f in families
    ]
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(min(args.jobs, len(jobs))) as pool:
        rows = pool.map(one, jobs, chunksize=1)
    saved = RESULTS / "skill_families.json"
    old = json.loads(saved.read_text())["rows"] if saved.exists() else []
    keep = {(r["family"], r["seed"]): r for r in old} | {(r["family"], r["seed"]): r for r in rows}
    rows = [keep[k] for k in sorted(keep, key=lambda k: (list(FAMILIES).index(k[0]), k[1]))]
    saved.write_text(json.dumps({"rows": rows, "machine_cores": 2}, indent=1))
    print(table(rows))
    print(f"mean ER {np.mean([r['explored_ratio'] for r in rows]):.2f} over {len(rows)} rows")


if __name__ == "__main__":
    main()
