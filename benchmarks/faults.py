"""Fault injection: a real training job — `paramimic train` with a local Ray, the API
and a Redis server this script owns (so that it can kill and restart it) — gets each fault
injected several times at random moments; per fault it reports what happened.

Faults: SIGKILL of a rollout actor, of the sampler actor, of the Redis server (restarted after a
pause), of the API process, of the learner (then `--resume`); SIGSTOP of a rollout actor for
longer than actors.fragment_timeout; a full disk under the checkpoint directory (a small tmpfs,
needs root; skipped otherwise) that is freed again; a corrupted latest.pt (then SIGKILL of the
learner and `--resume`, which must fall back to the newest readable ckpt file).

Per fault: times injected; outcome per injection (continued: iterations went on; resumed: the
relaunched learner went on from a checkpoint; otherwise what it printed); episodes the learner
lost (episodes the sampler counted, by unique episode id, that no fragment brought to the
learner); episodes double-counted (the sampler's episode counter minus its unique ids); elites
lost (the [L21] elite count just before an injection minus the count after recovery, when
lower); seconds to recover (injection to 2 more iterations, or to the API answering again);
processes left behind after the run ended (anything the launchers started still alive 30 s
later; Ray's processes included).

    python benchmarks/faults.py [--faults actor,sampler,...] [--times 3] [--seed 0]

Writes benchmarks/results/faults.json. The job is an [L21] skill run on the planar walker
(configs/walker_jump.yaml, 2 actors x 4 envs, 1,024 steps per iteration, so that there are
elites to lose), fragment timeout 10 s.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import psutil
import redis
import yaml
from tabulate import tabulate

from services.keys import RunKeys
from services.launch.redis_server import EmbeddedRedis

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"

FAULTS = ("actor", "sampler", "redis", "api", "learner", "actor_stop", "disk_full", "corrupt")
RECOVERY_LIMIT = 240.0  # seconds after which an injection counts as not recovered
CONFIG = {
    "actors": {"num_actors": 2, "num_envs": 4, "fragment_timeout": 10.0, "lost_timeout": 120.0},
    "ppo": {"num_steps": 1024, "minibatch_size": 256, "num_epochs": 2},
    "train": {"total_steps": 10**9, "checkpoint_every": 2},
}


def _table(header, rows) -> str:
    """A GitHub Markdown table."""
    return tabulate(list(rows), headers=list(header), tablefmt="github", disable_numparse=True)


class Job:
    """One `paramimic train` process (a launcher) and every process it started."""

    def __init__(self, cfg: Path, run_dir: Path, redis_url: str, *extra: str) -> None:
        self.log = (run_dir.parent / f"{run_dir.name}.log").open("a")
        env = os.environ | {"COLUMNS": "200", "RAY_ADDRESS": "", "PYTHONPATH": str(ROOT)}
        env["REDIS_URL"] = redis_url  # `train --redis-url` from the environment: not on argv
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-X",
                "faulthandler",  # SIGABRT dumps every thread's stack into the log
                "-m",
                "services.cli",
                "train",
                str(cfg),
                "--run-dir",
                str(run_dir),
                "--api-port",
                "0",
                *extra,
            ],  # fmt: skip
            stdout=self.log,
            stderr=subprocess.STDOUT,
            env=env,
        )
        self.seen: dict[int, psutil.Process] = {}
        threading.Thread(target=self._watch, daemon=True).start()

    def _watch(self) -> None:
        me = psutil.Process(self.proc.pid)
        while self.proc.poll() is None:
            with contextlib.suppress(psutil.Error):
                for p in me.children(recursive=True):
                    self.seen.setdefault(p.pid, p)
            time.sleep(0.2)

    def processes(self, name: str) -> list[psutil.Process]:
        out = []
        for p in list(self.seen.values()):
            with contextlib.suppress(psutil.Error):
                if p.is_running() and name in " ".join([p.name(), *p.cmdline()]):
                    out.append(p)
        return out

    def left_behind(self, keep: set[int]) -> list[str]:
        names = []
        for p in self.seen.values():
            with contextlib.suppress(psutil.Error):
                if p.pid not in keep and p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                    names.append(p.name())
        return names


class Suite:
    def __init__(self, work: Path, times: int, rng: random.Random) -> None:
        self.work, self.times, self.rng = work, times, rng
        self.server = EmbeddedRedis(work / "redis")
        self.url = self.server.start()
        self.client = redis.Redis.from_url(self.url, decode_responses=True)
        base = yaml.safe_load((ROOT / "configs" / "walker_jump.yaml").read_text())
        for section, values in CONFIG.items():
            base[section] = base.get(section, {}) | values
        self.cfg = work / "faults.yaml"
        self.cfg.write_text(yaml.safe_dump(base))

    # --- state read from the job's Redis -----------------------------------------------------

    def run_id(self, run_dir: Path) -> str | None:
        path = run_dir / "run_id"
        return path.read_text().strip() if path.exists() else None

    def progress(self, run_dir: Path) -> dict:
        run = self.run_id(run_dir)
        if run is None:
            return {}
        with contextlib.suppress(redis.RedisError):
            raw = self.client.hgetall(RunKeys(run).progress)
            return {k: json.loads(v) for k, v in raw.items()}
        return {}

    def iteration(self, run_dir: Path) -> int:
        return int(self.progress(run_dir).get("iteration") or 0)

    def summary(self, run_dir: Path) -> dict:
        with contextlib.suppress(redis.RedisError, TypeError):
            return json.loads(self.client.hget(RunKeys(self.run_id(run_dir)).curriculum, "summary"))
        return {}

    def api_url(self, run_dir: Path) -> str | None:
        with contextlib.suppress(redis.RedisError, TypeError):
            return self.client.hget(RunKeys(self.run_id(run_dir)).meta, "api_url") or None
        return None

    def wait(self, predicate, timeout: float = RECOVERY_LIMIT) -> float | None:
        start = time.monotonic()
        while time.monotonic() - start < timeout:
            with contextlib.suppress(Exception):
                if predicate():
                    return time.monotonic() - start
            time.sleep(0.25)
        return None

    # --- one fault -----------------------------------------------------------------------------

    def run_fault(self, fault: str) -> dict:
        run_dir = self.work / f"run-{fault}"
        mounted = False
        if fault == "disk_full":
            if os.geteuid() != 0 or shutil.which("mount") is None:
                return {"fault": fault, "skipped": "needs root to mount a tmpfs"}
            (run_dir / "checkpoints").mkdir(parents=True)
            subprocess.run(["mount", "-t", "tmpfs", "-o", "size=32m", "tmpfs",
                            str(run_dir / "checkpoints")], check=True)  # fmt: skip
            mounted = True
        jobs = [Job(self.cfg, run_dir, self.url)]
        row: dict = {"fault": fault, "injected": 0, "outcomes": [], "recovery_seconds": [],
                     "elites_lost": 0, "messages": []}  # fmt: skip
        try:
            if self.wait(lambda: self.iteration(run_dir) >= 4, 300) is None:
                raise RuntimeError(f"{fault}: the job did not start: see {run_dir}.log")
            for _ in range(self.times):
                time.sleep(self.rng.uniform(3.0, 12.0))
                elites = self.summary(run_dir).get("elites", 0)
                outcome, seconds = self.inject(fault, jobs, run_dir)
                row["injected"] += 1
                row["outcomes"].append(outcome)
                row["recovery_seconds"].append(seconds)
                after = self.summary(run_dir).get("elites", 0)
                row["elites_lost"] += max(0, elites - after)
            jobs[-1].proc.send_signal(signal.SIGINT)
            try:
                jobs[-1].proc.wait(180)
            except subprocess.TimeoutExpired:  # a stack dump into the log, then the outcome
                jobs[-1].proc.send_signal(signal.SIGABRT)
                time.sleep(5.0)
                row["messages"].append("did not stop within 180 s of SIGINT: " + self.tail(run_dir))
        finally:
            for job in jobs:
                if job.proc.poll() is None:
                    job.proc.kill()
        time.sleep(30.0)  # Ray reaps its own processes
        keep = {self.server.process.pid}
        row["processes_left"] = sorted(n for job in jobs for n in job.left_behind(keep))
        if mounted:
            subprocess.run(["umount", str(run_dir / "checkpoints")], check=False)
        row.update(self.counts(run_dir))
        return row

    def counts(self, run_dir: Path) -> dict:
        """Episodes lost to the learner and double-counted by the sampler, from Redis."""
        keys = RunKeys(self.run_id(run_dir))
        unique = self.client.scard(keys.seen)
        counted = int(self.summary(run_dir).get("episodes", 0))
        learner = int(self.progress(run_dir).get("episodes_total") or 0)
        return {
            "sampler_unique_episodes": unique,
            "learner_episodes": learner,
            "episodes_lost": max(0, unique - learner),
            "episodes_double_counted": max(0, counted - unique),
        }

    def inject(self, fault: str, jobs: list[Job], run_dir: Path) -> tuple[str, float | None]:
        job = jobs[-1]
        it = self.iteration(run_dir)
        went_on = lambda: self.iteration(run_dir) >= it + 2  # noqa: E731
        if fault in ("actor", "actor_stop"):
            victim = self.rng.choice(job.processes("ray::RolloutActor"))
            if fault == "actor":
                victim.kill()
            else:
                victim.suspend()  # longer than the fragment timeout: the learner kills it
                threading.Timer(20.0, lambda: _quietly(victim.resume)).start()
        elif fault == "sampler":
            job.processes("ray::SamplerActor")[0].kill()
        elif fault == "redis":
            self.server.kill()
            time.sleep(3.0)
            self.server.start()
        elif fault == "api":
            url = self.api_url(run_dir)
            [p for p in job.processes("services.cli") if "api" in p.cmdline()][0].kill()
            seconds = self.wait(lambda: httpx.get(f"{url}/health", timeout=2).status_code == 200)
            return ("continued" if seconds is not None else "api not back"), seconds
        elif fault == "disk_full":
            filler = run_dir / "checkpoints" / "filler"
            with contextlib.suppress(OSError), filler.open("wb") as f:
                while True:
                    f.write(b"\0" * (1 << 20))
            failed = self.wait(lambda: "checkpoint_failed" in self.events(run_dir), 120)
            filler.unlink()
            if failed is None:
                return "no checkpoint failed", None
            written = self.wait(lambda: self.checkpointed_after(run_dir, it + 2))
            return ("continued" if written is not None else "no checkpoint after"), written
        elif fault in ("learner", "corrupt"):
            if fault == "corrupt":  # a new inode: ckpt_* keep their bytes
                latest = run_dir / "checkpoints" / "latest.pt"
                garbage = latest.with_name(".garbage")
                garbage.write_bytes(os.urandom(4096))
                os.replace(garbage, latest)
            start = time.monotonic()
            job.proc.kill()
            job.proc.wait(60)
            time.sleep(1.0)
            resumes = len(self.resumes(run_dir))
            jobs.append(Job(self.cfg, run_dir, self.url, "--resume"))
            back = self.wait(lambda: len(self.resumes(run_dir)) > resumes)
            if back is None:
                return "not resumed: " + self.tail(run_dir), None
            resumed_at = self.resumes(run_dir)[-1]
            seconds = self.wait(lambda: self.iteration(run_dir) >= resumed_at + 2)
            total = None if seconds is None else time.monotonic() - start
            return ("resumed" if total is not None else "resumed, no progress"), total
        seconds = self.wait(went_on)
        return ("continued" if seconds is not None else "stalled: " + self.tail(run_dir)), seconds

    def events(self, run_dir: Path) -> list[str]:
        entries = self.client.xrange(RunKeys(self.run_id(run_dir)).events)
        return [e["type"] for _, e in entries]

    def checkpointed_after(self, run_dir: Path, iteration: int) -> bool:
        names = [p.name for p in (run_dir / "checkpoints").glob("ckpt_*.pt")]
        return any(int(re.findall(r"\d+", n)[0]) >= iteration for n in names)

    def resumes(self, run_dir: Path) -> list[int]:
        """The iterations the launches of this run resumed at, in order (from its log)."""
        log = (run_dir.parent / f"{run_dir.name}.log").read_text()
        return [int(i) for i in re.findall(r"resumed at iteration (\d+)", log)]

    def tail(self, run_dir: Path) -> str:
        return (run_dir.parent / f"{run_dir.name}.log").read_text()[-300:].replace("\n", " | ")

    def close(self) -> None:
        self.server.stop()


def _quietly(f) -> None:
    with contextlib.suppress(psutil.Error):
        f()


def table(rows: list[dict]) -> str:
    """The README's fault table."""
    header = ["fault", "injected", "outcome", "episodes lost / double-counted", "elites lost",
              "recovery s (mean, max)", "processes left"]  # fmt: skip
    lines = []
    for r in rows:
        if "error" in r or "skipped" in r:
            lines.append([r["fault"], "–", r.get("error") or r.get("skipped"), "", "", "", ""])
            continue
        outcomes = sorted(set(r["outcomes"]))
        counts = ", ".join(f"{r['outcomes'].count(o)}x {o}" for o in outcomes)
        secs = [x for x in r["recovery_seconds"] if x is not None]
        rec = f"{sum(secs) / len(secs):.1f}, {max(secs):.1f}" if secs else "–"
        left = ", ".join(r["processes_left"]) or "0"
        lost = f"{r['episodes_lost']} / {r['episodes_double_counted']}"
        lines.append([r["fault"], r["injected"], counts, lost, r["elites_lost"], rec, left])
    return _table(header, lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--faults", default=",".join(FAULTS))
    ap.add_argument("--times", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--table", action="store_true", help="print faults.json as a markdown table")
    args = ap.parse_args()
    if args.table:
        print(table(json.loads((RESULTS / "faults.json").read_text())["rows"]))
        return
    faults = args.faults.split(",")
    unknown = set(faults) - set(FAULTS)
    if unknown:
        ap.error(f"unknown faults {sorted(unknown)}; faults: {', '.join(FAULTS)}")
    work = Path(tempfile.mkdtemp(prefix="paramimic-faults-"))
    suite = Suite(work, args.times, random.Random(args.seed))
    rows = []
    out = RESULTS / "faults.json"
    try:
        for fault in faults:
            try:
                row = suite.run_fault(fault)
            except Exception as e:  # the suite goes on; the row says what broke
                row = {"fault": fault, "error": f"{type(e).__name__}: {e}"[:500]}
            rows.append(row)
            print(json.dumps(row), flush=True)
            previous = json.loads(out.read_text())["rows"] if out.exists() else []
            merged = {r["fault"]: r for r in previous} | {r["fault"]: r for r in rows}
            out.write_text(json.dumps({
                "command": "python benchmarks/faults.py " + " ".join(sys.argv[1:]),
                "rows": [merged[f] for f in FAULTS if f in merged],
            }, indent=1))  # fmt: skip
    finally:
        suite.close()
    print(f"wrote {out}; logs in {work}")


if __name__ == "__main__":
    main()
