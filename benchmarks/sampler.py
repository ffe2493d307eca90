"""Sampler and API latency. Not a timed test.

1. The sampler actor on a local Ray with an embedded Redis, with 10^3, 10^4 and 10^5 ingested
   episodes stored: latency of `next_tasks(64)` and of ingesting a batch of 16 new episode
   summaries, called from the driver through Ray (what an actor sees) and on the service
   in-process (the sampler's own cost), p50/p99 over --calls calls each.
2. The API while `paramimic train configs/walker_legs.yaml` runs (2 rollout actors on this
   machine): `wrk` (Debian's package) on GET /runs/{run}/progress for --seconds, 1 thread, once
   per --connections value; req/s and p50/p99, with the training rate without and during each
   load. Without wrk, an asyncio httpx load generator does the same (slower client).

    python benchmarks/sampler.py [--calls 1000] [--seconds 20] [--connections 4,16]

Writes benchmarks/results/sampler/sampler.json. Targets: sampler p99 < 5 ms at 10^5; API >= 500
req/s with p99 < 50 ms while training.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
import ray

from paramimic.config import load_config
from services.launch.redis_server import EmbeddedRedis
from services.learner.cluster import start_private
from services.sampler.actor import start_sampler
from services.sampler.service import SamplerService

ROOT = Path(__file__).resolve().parent.parent
CONFIG = "configs/walker_legs.yaml"


def _episodes(start: int, n: int, d: int) -> list[dict]:
    return [
        {
            "episode_id": f"bench-{i}",
            "task": [1.0] * d,
            "return": 10.0,
            "length": 100,
            "fell": False,
            "diverged": False,
            "reward_terms": {},
        }
        for i in range(start, start + n)
    ]


def _percentiles(seconds: list[float]) -> dict:
    ms = np.asarray(seconds) * 1e3
    return {"p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99))}


def _timed(call, n: int) -> list[float]:
    out = []
    for _ in range(n):
        t = time.perf_counter()
        call()
        out.append(time.perf_counter() - t)
    return out


def sampler_latency(redis_url: str, stored: int, calls: int) -> dict:
    cfg = load_config(ROOT / CONFIG)
    config = cfg.model_dump(mode="json")
    d = len(cfg.task)
    run_id = f"bench-sampler-{stored}-{os.urandom(2).hex()}"
    actor = start_sampler(config, redis_url, run_id)
    try:
        for start in range(0, stored, 1000):  # fill the store the way actors do
            ray.get(actor.ingest.remote(_episodes(start, min(1000, stored - start), d)))
        assert ray.get(actor.seen_count.remote()) == stored
        next_id = [stored]

        def ingest_remote():
            ray.get(actor.ingest.remote(_episodes(next_id[0], 16, d)))
            next_id[0] += 16

        remote = {
            "next_tasks_64": _percentiles(
                _timed(lambda: ray.get(actor.next_tasks.remote(64, "bench")), calls)
            ),
            "ingest_16": _percentiles(_timed(ingest_remote, calls)),
        }
    finally:
        ray.kill(actor)
    service = SamplerService(config, redis_url, run_id)  # the same run, in-process

    def ingest_local():
        service.ingest(_episodes(next_id[0], 16, d))
        next_id[0] += 16

    local = {
        "next_tasks_64": _percentiles(_timed(lambda: service.next_tasks(64, "bench"), calls)),
        "ingest_16": _percentiles(_timed(ingest_local, calls)),
    }
    rng = np.random.default_rng(0)
    dims = [d, *cfg.curriculum.marginal_hidden, 1]
    layers = [(rng.normal(size=(a, b)) * 0.3, np.zeros(b)) for a, b in itertools.pairwise(dims)]
    refill = _timed(lambda: service.update_marginal(layers, 1.0, 1, refill=True), 10)
    return {
        "stored_episodes": service.seen_count(),
        "through_ray": remote,
        "in_process": local,
        "update_marginal_with_mcmc_refill": _percentiles(refill),
    }


def _wrk(url: str, seconds: int, connections: int) -> dict:
    out = subprocess.run(
        ["wrk", "-t1", f"-c{connections}", f"-d{seconds}s", "--latency", url],
        capture_output=True,
        text=True,
        check=True,
    ).stdout

    def ms(label: str) -> float:
        value, unit = re.search(rf"{label}\s+([\d.]+)(us|ms|s)\b", out).groups()
        return float(value) * {"us": 1e-3, "ms": 1.0, "s": 1e3}[unit]

    errors = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    return {
        "tool": "wrk",
        "requests_per_s": float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1)),
        "p50_ms": ms("50%"),
        "p99_ms": ms("99%"),
        "non_2xx": int(errors.group(1)) if errors else 0,
        "raw": out,
    }


def _python_load(url: str, seconds: int, connections: int) -> dict:
    async def run() -> tuple[list[float], int]:
        latencies: list[float] = []
        bad = 0
        deadline = time.perf_counter() + seconds
        async with httpx.AsyncClient(limits=httpx.Limits(max_connections=connections)) as c:

            async def worker():
                nonlocal bad
                while time.perf_counter() < deadline:
                    t = time.perf_counter()
                    r = await c.get(url)
                    latencies.append(time.perf_counter() - t)
                    bad += r.status_code != 200

            await asyncio.gather(*(worker() for _ in range(connections)))
        return latencies, bad

    latencies, bad = asyncio.run(run())
    return {
        "tool": "python httpx",
        "requests_per_s": len(latencies) / seconds,
        **_percentiles(latencies),
        "non_2xx": bad,
    }


def rate(a: dict, b: dict) -> float:
    """Training env steps/s between two /progress answers."""
    return (b["env_steps"] - a["env_steps"]) / (b["updated_at"] - a["updated_at"])


def api_under_training(seconds: int, connections: list[int]) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        env = os.environ | {"COLUMNS": "200", "RAY_ADDRESS": ""}
        proc = subprocess.Popen(
            [sys.executable, "-m", "services.cli", "train", str(ROOT / CONFIG),
             "--run-dir", f"{tmp}/run", "--api-port", "0", "--total-steps", "1000000000"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=ROOT,
        )  # fmt: skip
        try:
            url = None
            for line in proc.stdout:
                m = re.search(r"API: (http://127\.0\.0\.1:\d+)", line)
                if m:
                    url = m.group(1)
                    break
            assert url, "the launcher printed no API URL"
            c = httpx.Client(base_url=url, timeout=10)
            run = c.get("/runs").json()[0]["run_id"]

            def iteration() -> int:
                return c.get(f"/runs/{run}/progress").json()["iteration"]

            while iteration() < 3:  # warmed up
                time.sleep(0.5)
            quiet_from = c.get(f"/runs/{run}/progress").json()
            time.sleep(seconds)
            quiet_to = c.get(f"/runs/{run}/progress").json()
            target = f"{url}/runs/{run}/progress"
            loads = []
            for n in connections:
                before = c.get(f"/runs/{run}/progress").json()
                load = (
                    _wrk(target, seconds, n)
                    if shutil.which("wrk")
                    else _python_load(target, seconds, n)
                )
                after = c.get(f"/runs/{run}/progress").json()
                loads.append(
                    {"connections": n, **load, "training_steps_per_s": rate(before, after)}
                )
        finally:
            proc.send_signal(signal.SIGINT)
            proc.wait(300)

    return {
        "endpoint": "GET /runs/{run}/progress",
        "seconds": seconds,
        "training_steps_per_s_without_load": rate(quiet_from, quiet_to),
        "loads": loads,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=1000)
    ap.add_argument("--seconds", type=int, default=20)
    ap.add_argument("--connections", default="4,16", help="wrk connections, one load per value")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/sampler/sampler.json")
    args = ap.parse_args()
    result: dict = {"cpus": os.cpu_count(), "config": CONFIG}
    start_private()  # a cluster of its own, as `paramimic train` starts
    try:
        with tempfile.TemporaryDirectory() as tmp, EmbeddedRedis(Path(tmp)) as server:
            result["sampler"] = {
                str(n): sampler_latency(server.url, n, args.calls) for n in (10**3, 10**4, 10**5)
            }
    finally:
        ray.shutdown()
    connections = [int(n) for n in args.connections.split(",")]
    result["api"] = api_under_training(args.seconds, connections)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    for n, row in result["sampler"].items():
        print(f"stored {n:>6}: through Ray {row['through_ray']}  in-process {row['in_process']}")
    api = result["api"]
    print(f"training without API load: {api['training_steps_per_s_without_load']:.0f} steps/s")
    for x in api["loads"]:
        print(
            f"API ({x['tool']}, {x['connections']} connections): {x['requests_per_s']:.0f} req/s, "
            f"p50 {x['p50_ms']:.1f} ms, p99 {x['p99_ms']:.1f} ms, non-2xx {x['non_2xx']}; "
            f"training {x['training_steps_per_s']:.0f} steps/s"
        )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
