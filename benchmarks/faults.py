"""Fault injection: a real training job — `paramimic train` with a local Ray, the API and a
Redis server (this script's, which it reads the run's state from; the `redis` row's job runs in
laptop mode with its launcher's embedded one) — gets each fault injected several times at
random moments; per fault it reports what happened.

Faults: none (the control row: what a run without faults shows); SIGKILL of a rollout actor, of
the sampler actor, of the API process, of the learner (then `--resume`); SIGKILL of the Redis
server of a laptop run (the launcher's embedded one: the launcher, not this script, restarts
it); SIGSTOP of a rollout actor for longer than actors.fragment_timeout; the whole run directory
on a disk that fills up and is freed again (a small tmpfs, needs root; skipped otherwise); a
damaged latest.pt (by turns: bytes that are no archive, NaN written into a tensor inside a valid
archive, flipped bytes inside a valid archive), then SIGKILL of the learner and `--resume`,
which must refuse it and fall back to the newest ckpt file that verifies.

Per fault: times injected; outcome per injection (continued: iterations went on; resumed: the
relaunched learner went on from a checkpoint; otherwise what it printed); episodes by id, end
to end: lost (ids the sampler counted that no iteration learned from, from the run's `seen` and
`learned` sets in Redis; the control row shows what a stop leaves in flight), uncounted (ids
learned from that the sampler never counted), double-counted (the sampler's episode counter
minus its unique ids, plus the learner's count of learned episodes minus its unique ids);
elites lost by key (an [L21] elite's key present just before an injection and absent after
recovery, with no elite of higher fitness within the elite radius of it after: a replacement by
the elite rule is not a loss); seconds to recover (injection to 2 more iterations, or to the API
answering again); processes left behind after the run ended (anything the launchers started
still alive 30 s later; Ray's processes included).

    python benchmarks/faults.py [--faults actor,sampler,...] [--times 3] [--seed 0]

Writes benchmarks/results/faults/faults.json and its table into docs/security.md. The job is an
[L21] skill run on the planar walker (configs/walker_jump.yaml, 2 actors x 4 envs, 1,024 steps per
iteration, so that there are elites to lose), fragment timeout 10 s.
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
import zipfile
from pathlib import Path

import httpx
import numpy as np
import psutil
import redis
import yaml
from tabulate import tabulate

from paramimic.config import load_config
from paramimic.curriculum.elite_set import EliteSet
from paramimic.task_space import TaskSpace
from services.keys import RunKeys
from services.launch.redis_server import EmbeddedRedis, redis_server_binary

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "faults"

FAULTS = ("none", "actor", "sampler", "redis", "api", "learner", "actor_stop", "disk_full",
          "corrupt")  # fmt: skip
VERSION = 2  # of what a row checks: rows of another version are not merged
DAMAGE = ("garbage", "nan", "bits")  # how `corrupt` damages latest.pt, by turns
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

    def __init__(self, cfg: Path, run_dir: Path, redis_url: str | None, *extra: str) -> None:
        self.log = (run_dir.parent / f"{run_dir.name}.log").open("a")
        env = os.environ | {"COLUMNS": "200", "RAY_ADDRESS": "", "PYTHONPATH": str(ROOT)}
        env.pop("REDIS_URL", None)
        if redis_url is not None:  # else laptop mode: the launcher's embedded Redis
            env["REDIS_URL"] = redis_url  # `train --redis-url` from the environment: not argv
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
        self.suite_client = self.client = redis.Redis.from_url(self.url, decode_responses=True)
        base = yaml.safe_load((ROOT / "configs" / "walker_jump.yaml").read_text())
        for section, values in CONFIG.items():
            base[section] = base.get(section, {}) | values
        self.cfg = work / "faults.yaml"
        self.cfg.write_text(yaml.safe_dump(base))
        self.elite_radius = load_config(self.cfg).curriculum.skill.elite_radius
        self.damage = 0

    def embedded_client(self, run_dir: Path) -> redis.Redis:
        """A client of a laptop run's own Redis (its port and password from its redis.conf,
        which this script, as the same user, may read)."""
        conf = (run_dir / "redis" / "redis.conf").read_text()
        port = int(re.search(r"^port (\d+)$", conf, re.M).group(1))
        password = re.search(r'^requirepass "(.*)"$', conf, re.M).group(1)
        return redis.Redis(port=port, password=password, decode_responses=True,
                           socket_timeout=5)  # fmt: skip

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
            run_dir.mkdir(parents=True)  # the whole run directory on the small disk
            subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64m", "tmpfs", str(run_dir)],
                           check=True)  # fmt: skip
            mounted = True
        laptop = fault == "redis"  # the launcher's embedded Redis, supervised by the launcher
        jobs = [Job(self.cfg, run_dir, None if laptop else self.url)]
        row: dict = {"fault": fault, "injected": 0, "outcomes": [], "recovery_seconds": [],
                     "elites_lost": 0, "elites_replaced": 0, "messages": []}  # fmt: skip
        self.client = self.suite_client
        try:
            if laptop:
                self.wait(lambda: (run_dir / "redis" / "redis.conf").exists(), 120)
                self.client = self.embedded_client(run_dir)
            if self.wait(lambda: self.iteration(run_dir) >= 4, 300) is None:
                raise RuntimeError(f"{fault}: the job did not start: see {run_dir}.log")
            for _ in range(self.times if fault != "none" else 1):
                time.sleep(self.rng.uniform(3.0, 12.0))
                before = self.elites(run_dir)
                outcome, seconds = self.inject(fault, jobs, run_dir)
                row["injected"] += fault != "none"
                row["outcomes"].append(outcome)
                row["recovery_seconds"].append(seconds)
                lost, replaced = self.elites_gone(before, self.elites(run_dir), run_dir)
                row["elites_lost"] += lost
                row["elites_replaced"] += replaced
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
        if laptop:  # its Redis went with its launcher: read what it kept from its AOF
            self.client = self.restart_embedded(run_dir, keep)
        row["processes_left"] = sorted(n for job in jobs for n in job.left_behind(keep))
        row.update(self.counts(run_dir))
        if laptop:
            with contextlib.suppress(redis.RedisError):
                self.client.shutdown(nosave=True)
        if mounted:
            subprocess.run(["umount", "-l", str(run_dir)], check=False)
        return row

    def restart_embedded(self, run_dir: Path, keep: set[int]) -> redis.Redis:
        """A stopped laptop run's Redis started again on its data (to count what it kept)."""
        conf = run_dir / "redis" / "redis.conf"
        proc = subprocess.Popen([redis_server_binary(), str(conf)], stdout=subprocess.DEVNULL)
        keep.add(proc.pid)
        client = self.embedded_client(run_dir)
        self.wait(client.ping, 30)
        return client

    def counts(self, run_dir: Path) -> dict:
        """Episodes by id, end to end: the ids the sampler counted (`seen`) against the ids the
        learner's iterations learned from (`learned`), from the run's Redis."""
        keys = RunKeys(self.run_id(run_dir))
        seen, learned = self.client.smembers(keys.seen), self.client.smembers(keys.learned)
        counted = int(self.summary(run_dir).get("episodes", 0))
        learned_count = int(self.client.hget(keys.meta, "learned_episodes") or 0)
        return {
            "sampler_unique_episodes": len(seen),
            "learner_unique_episodes": len(learned),
            "episodes_lost": len(seen - learned),
            "episodes_uncounted": len(learned - seen),
            "episodes_double_counted": max(0, counted - len(seen))
            + max(0, learned_count - len(learned)),
        }

    def elites(self, run_dir: Path) -> dict:
        """The [L21] elite set the sampler last wrote: params, fitness and keys."""
        text = self.client.hget(RunKeys(self.run_id(run_dir)).curriculum, "elites")
        return json.loads(text) if text else {"params": [], "fitness": [], "keys": []}

    def elites_gone(self, before: dict, after: dict, run_dir: Path) -> tuple[int, int]:
        """(lost, replaced): elites of `before` whose keys `after` lacks, split by whether an
        elite of `after` within the elite radius beats their fitness (the elite rule replaced
        them) or not (lost)."""
        gone = [i for i, k in enumerate(before["keys"]) if k not in set(after["keys"])]
        if not gone:
            return 0, 0
        space = TaskSpace.from_ranges(self.summary(run_dir)["task_ranges"])
        now = EliteSet(space.dim, space.metric)
        now.from_state(after)
        lost = 0
        for i in gone:
            near = now.neighbours(np.asarray(before["params"][i]), self.elite_radius)
            lost += not (len(near) and np.any(now.fitness[near] > before["fitness"][i]))
        return lost, len(gone) - lost

    def inject(self, fault: str, jobs: list[Job], run_dir: Path) -> tuple[str, float | None]:
        job = jobs[-1]
        it = self.iteration(run_dir)
        went_on = lambda: self.iteration(run_dir) >= it + 2  # noqa: E731
        if fault == "none":
            pass
        elif fault in ("actor", "actor_stop"):
            victim = self.rng.choice(job.processes("ray::RolloutActor"))
            if fault == "actor":
                victim.kill()
            else:
                victim.suspend()  # longer than the fragment timeout: the learner kills it
                threading.Timer(20.0, lambda: _quietly(victim.resume)).start()
        elif fault == "sampler":
            job.processes("ray::SamplerActor")[0].kill()
        elif fault == "redis":  # the launcher notices between iterations and restarts it
            job.processes("redis-server")[0].kill()
        elif fault == "api":
            url = self.api_url(run_dir)
            [p for p in job.processes("services.cli") if "api" in p.cmdline()][0].kill()
            seconds = self.wait(lambda: httpx.get(f"{url}/health", timeout=2).status_code == 200)
            return ("continued" if seconds is not None else "api not back"), seconds
        elif fault == "disk_full":
            filler = run_dir / "filler"
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
            if fault == "corrupt":
                self.damage_latest(run_dir / "checkpoints" / "latest.pt")
            start, fallbacks = time.monotonic(), len(self.fallbacks(run_dir))
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
            outcome = "resumed" if total is not None else "resumed, no progress"
            if fault == "corrupt":  # it must have refused the damaged latest.pt
                refused = len(self.fallbacks(run_dir)) > fallbacks
                outcome += " (latest.pt refused)" if refused else " FROM THE DAMAGED FILE"
            return outcome, total
        seconds = self.wait(went_on)
        return ("continued" if seconds is not None else "stalled: " + self.tail(run_dir)), seconds

    def damage_latest(self, latest: Path) -> None:
        """Damage latest.pt as a new inode (the ckpt_* file it links keeps its bytes), by turns
        in one of the DAMAGE ways; the two inside a valid archive reach torch's loader."""
        kind = DAMAGE[self.damage % len(DAMAGE)]
        self.damage += 1
        damaged = latest.with_name(".damaged")
        if kind == "garbage":
            damaged.write_bytes(os.urandom(4096))
        else:
            with zipfile.ZipFile(latest) as src, zipfile.ZipFile(damaged, "w") as out:
                members = src.infolist()
                tensors = [m for m in members if "/data/" in m.filename and m.file_size >= 64]
                victim = max(tensors, key=lambda m: m.file_size).filename
                for m in members:
                    data = bytearray(src.read(m))
                    if m.filename == victim:
                        if kind == "nan":  # float32 NaN over its first 16 values
                            data[:64] = b"\x00\x00\xc0\x7f" * 16
                        else:  # finite garbage: only the manifest can tell
                            data[:8] = bytes(b ^ 0x5A for b in data[:8])
                    out.writestr(m, bytes(data), compress_type=zipfile.ZIP_STORED)
        os.replace(damaged, latest)

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

    def fallbacks(self, run_dir: Path) -> list[str]:
        """The launches' warnings that latest.pt was refused for an older ckpt file."""
        log = (run_dir.parent / f"{run_dir.name}.log").read_text()
        return re.findall(r"latest\.pt (.*?); using ckpt_\d+\.pt instead", log)

    def tail(self, run_dir: Path) -> str:
        return (run_dir.parent / f"{run_dir.name}.log").read_text()[-300:].replace("\n", " | ")

    def close(self) -> None:
        self.server.stop()


def _quietly(f) -> None:
    with contextlib.suppress(psutil.Error):
        f()


def table(rows: list[dict]) -> str:
    """The fault table of docs/security.md."""
    header = ["fault", "injected", "outcome", "episodes lost / uncounted / double-counted",
              "elites lost (replaced)", "recovery s (mean, max)", "processes left"]  # fmt: skip
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
        of = r["sampler_unique_episodes"]
        lost = (f"{r['episodes_lost']} / {r['episodes_uncounted']} / "
                f"{r['episodes_double_counted']} of {of}")  # fmt: skip
        elites = f"{r['elites_lost']} ({r['elites_replaced']})"
        lines.append([r["fault"], r["injected"], counts, lost, elites, rec, left])
    return _table(header, lines)


DOCS = ROOT / "docs" / "security.md"
MARK = ("<!-- faults -->", "<!-- /faults -->")


def write_docs(result: dict) -> None:
    """The table and what it adds up to, between docs/security.md's marks."""
    rows = [r for r in result["rows"] if "outcomes" in r]
    injected = sum(r["injected"] for r in rows)
    went_on = sum(o.startswith(("continued", "resumed")) and "DAMAGED" not in o
                  for r in rows if r["fault"] != "none" for o in r["outcomes"])  # fmt: skip
    control = next((r for r in rows if r["fault"] == "none"), None)
    lines = [
        f"Written by `{result['command']}` on {result.get('date', 'an earlier day')}.",
        "",
        table(result["rows"]),
        "",
        f"{went_on} of {injected} injections continued or resumed; "
        f"{sum(r['episodes_lost'] for r in rows if r['fault'] != 'none')} episodes lost, "
        f"{sum(r['episodes_uncounted'] for r in rows)} uncounted and "
        f"{sum(r['episodes_double_counted'] for r in rows)} double-counted over all rows"
        + (f" (the control row alone: {control['episodes_lost']} lost)" if control else "")
        + f"; {sum(r['elites_lost'] for r in rows)} elites lost; "
        f"{sum(len(r['processes_left']) for r in rows)} processes left behind.",
    ]
    text = DOCS.read_text()
    start, end = text.index(MARK[0]) + len(MARK[0]), text.index(MARK[1])
    DOCS.write_text(text[:start] + "\n" + "\n".join(lines) + "\n" + text[end:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--faults", default=",".join(FAULTS))
    ap.add_argument("--times", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--table", action="store_true", help="print faults.json as a markdown table")
    ap.add_argument("--out", type=Path, default=RESULTS / "faults.json")
    args = ap.parse_args()
    if args.table:
        result = json.loads(args.out.read_text())
        print(table(result["rows"]))
        if args.out == RESULTS / "faults.json":
            write_docs(result)
        return
    faults = args.faults.split(",")
    unknown = set(faults) - set(FAULTS)
    if unknown:
        ap.error(f"unknown faults {sorted(unknown)}; faults: {', '.join(FAULTS)}")
    work = Path(tempfile.mkdtemp(prefix="paramimic-faults-"))
    suite = Suite(work, args.times, random.Random(args.seed))
    rows = []
    out = args.out
    try:
        for fault in faults:
            try:
                row = suite.run_fault(fault)
            except Exception as e:  # the suite goes on; the row says what broke
                row = {"fault": fault, "error": f"{type(e).__name__}: {e}"[:500]}
            rows.append(row)
            print(json.dumps(row), flush=True)
            before = json.loads(out.read_text()) if out.exists() else {}
            # rows of an earlier version of this script checked less: not merged
            previous = before.get("rows", []) if before.get("version") == VERSION else []
            merged = {r["fault"]: r for r in previous} | {r["fault"]: r for r in rows}
            result = {
                "version": VERSION,
                "command": "python benchmarks/faults.py " + " ".join(sys.argv[1:]),
                "date": time.strftime("%Y-%m-%d"),
                "rows": [merged[f] for f in FAULTS if f in merged],
            }
            out.write_text(json.dumps(result, indent=1))
            if out == RESULTS / "faults.json":
                write_docs(result)
    finally:
        suite.close()
    print(f"wrote {out}; logs in {work}")


if __name__ == "__main__":
    main()
