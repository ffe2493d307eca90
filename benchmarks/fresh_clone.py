"""The README's two commands on a fresh clone: `make train` and `make test`, timed.

Clones this checkout's HEAD into a temporary directory (with `../shared` beside it, as CI has
it), then runs, one after the other and alone on the machine:

1. `make .venv/.installed`, then `make train` (the install and the training timed apart; the
   run's metrics.jsonl gives its env steps, steps/s and its training falls at the start and end);
2. `make .venv/.installed-test`, then `make test` (pytest's own summary: passed, skipped, the
   seconds of the test run).

    python benchmarks/fresh_clone.py [--only train|test] [--keep]

Writes benchmarks/results/make_train/fresh_clone_<date>.json (the commit, the machine, each
phase's wall-clock) and keeps the run's metrics beside it. docs/results/make-train.md renders
every such file. Long (about 25 minutes on 2 cores): run it when nothing else runs.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "make_train"
SUMMARY = re.compile(r"=+ (.*?) in ([\d.]+)s")


def _timed(cmd: list[str], cwd: Path, log: Path) -> dict:
    """Wall-clock seconds and return code of a command (a failure keeps its log's last lines)."""
    start = time.monotonic()
    with log.open("w") as out:
        rc = subprocess.run(cmd, cwd=cwd, stdout=out, stderr=subprocess.STDOUT).returncode
    done = {"command": " ".join(cmd), "seconds": time.monotonic() - start, "returncode": rc}
    if rc != 0:
        done["log_tail"] = log.read_text(errors="replace").splitlines()[-40:]
    return done


def _training(clone: Path, config: str) -> dict:
    from paramimic.config import load_config

    run_dir = clone / load_config(clone / config).resolved_run_dir()
    lines = (run_dir / "metrics.jsonl").read_text().splitlines()
    rows = [r for r in map(json.loads, lines) if "env_steps" in r]
    falls = [r["fall_percent"] for r in rows]
    return {
        "config": config,
        "env_steps": rows[-1]["env_steps"],
        "iterations": len(rows),
        "steps_per_second": rows[-1]["env_steps"] / (rows[-1]["time"] - rows[0]["time"]),
        "training_falls_first_25": sum(falls[:25]) / len(falls[:25]),
        "training_falls_last_10": sum(falls[-10:]) / len(falls[-10:]),
        "metrics": run_dir / "metrics.jsonl",
    }


def _pytest_summary(log: Path) -> dict:
    """pytest's last summary line: counts by outcome and the seconds of the test run."""
    lines = [m for m in map(SUMMARY.search, log.read_text().splitlines()) if m]
    if not lines:
        return {}
    counts = dict((k, int(n)) for n, k in re.findall(r"(\d+) (\w+)", lines[-1].group(1)))
    return {"counts": counts, "test_seconds": float(lines[-1].group(2))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", choices=("train", "test"))
    ap.add_argument("--keep", action="store_true", help="keep the clone (its path is printed)")
    args = ap.parse_args()
    commit = subprocess.check_output(["git", "rev-parse", "HEAD"], cwd=ROOT, text=True).strip()
    tmp = Path(tempfile.mkdtemp(prefix="paramimic-fresh-"))
    clone = tmp / "paramimic"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
    (tmp / "shared").symlink_to((ROOT.parent / "shared").resolve())
    env_config = "configs/walker_legs.yaml"  # the Makefile's CONFIG default
    out: dict = {
        "commit": commit,
        "date": time.strftime("%Y-%m-%d"),
        "machine": {
            "cpus": os.cpu_count(),
            "processor": platform.processor() or platform.machine(),
            "python": platform.python_version(),
        },  # fmt: skip
    }
    stem = f"fresh_clone_{out['date']}"
    path = RESULTS / f"{stem}.json"
    if path.exists():  # `--only train` and `--only test` of one day make one file
        out = json.loads(path.read_text()) | out
    RESULTS.mkdir(parents=True, exist_ok=True)
    try:
        if args.only in (None, "train"):
            install = _timed(["make", ".venv/.installed"], clone, tmp / "install.log")
            train = _timed(["make", "train"], clone, tmp / "train.log")
            out["make_train"] = {"install": install, "train": train,
                                 "seconds": install["seconds"] + train["seconds"]}  # fmt: skip
            if train["returncode"] == 0:
                run = _training(clone, env_config)
                shutil.copy(run.pop("metrics"), RESULTS / f"{stem}_metrics.jsonl")
                out["make_train"]["run"] = run | {"metrics": f"{stem}_metrics.jsonl"}
            path.write_text(json.dumps(out, indent=2))
        if args.only in (None, "test"):
            install = _timed(["make", ".venv/.installed-test"], clone, tmp / "install-test.log")
            test = _timed(["make", "test"], clone, tmp / "test.log")
            out["make_test"] = {"install": install, "test": test,
                                "seconds": install["seconds"] + test["seconds"],
                                "pytest": _pytest_summary(tmp / "test.log")}  # fmt: skip
    finally:
        if args.keep:
            print(f"clone kept in {clone}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    path.write_text(json.dumps(out, indent=2))
    print(json.dumps(out, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
