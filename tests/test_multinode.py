"""More machines without containers: a Ray head and a worker node as separate `ray start`
processes (the worker in its own network namespace over a veth pair when root may make one,
else on loopback), token authentication on, a real Redis, and `paramimic train --ray-address
--redis-url` with its API. Actors sit on both nodes; the worker node leaves mid-run and training
goes on (the loss in the API's events); a new node joins and the pool grows again."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import httpx
import pytest
import yaml

from services.launch.local_cluster import LocalCluster
from services.launch.processes import free_port

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def cluster():
    c = LocalCluster(head_cpus=1, port=free_port("127.0.0.1"))
    try:
        c.start()
        yield c
    finally:
        c.stop()


def test_actors_on_two_nodes_survive_a_node_leaving(cluster, redis_server, tmp_path, wait_until):
    config = yaml.safe_load((ROOT / "configs" / "walker_legs.yaml").read_text())
    config["ppo"].update(num_steps=512, minibatch_size=256, num_epochs=2)
    config["actors"] = {"num_envs": 4, "num_actors": "auto", "lost_timeout": 300}
    config["train"].update(checkpoint_every=1000)
    (tmp_path / "cfg.yaml").write_text(yaml.safe_dump(config))
    cluster.add_worker(cpus=1)
    port = free_port("127.0.0.1")
    api = f"http://127.0.0.1:{port}"
    run_dir = tmp_path / "run"
    log = (tmp_path / "train.log").open("w")
    train = subprocess.Popen(
        [sys.executable, "-m", "services.cli", "train", str(tmp_path / "cfg.yaml"),
         "--ray-address", cluster.address, "--node-ip-address", cluster.head_ip,
         "--redis-url", redis_server.url,
         "--api-port", str(port), "--run-dir", str(run_dir), "--total-steps", "100000000"],
        cwd=ROOT, env=cluster.env, stdout=log, stderr=subprocess.STDOUT,
    )  # fmt: skip
    client = httpx.Client(base_url=api, timeout=10.0)

    def progress() -> dict:
        if train.poll() is not None:
            raise AssertionError(f"train exited {train.returncode}: {_tail(tmp_path)}")
        try:
            run_id = (run_dir / "run_id").read_text().strip()
            return client.get(f"/runs/{run_id}/progress").raise_for_status().json()
        except (OSError, httpx.HTTPError):
            return {}

    def events() -> list[str]:
        run_id = (run_dir / "run_id").read_text().strip()
        return [e["type"] for e in client.get(f"/runs/{run_id}/events").json()]

    try:
        # one actor per CPU of the cluster (auto): one on the head, one on the worker node
        p = wait_until(
            lambda: (q := progress()).get("iteration", 0) >= 2 and q, 300, "2 iterations"
        )
        assert (p["actors"], p["nodes"]) == (2, 2), p
        cluster.workers[0].stop()  # the node leaves mid-run
        lost_at = wait_until(
            lambda: "node_lost" in events() and progress()["iteration"], 180, "node_lost event"
        )
        p = wait_until(
            lambda: (q := progress())["iteration"] >= lost_at + 2 and q, 300, "training on"
        )
        assert (p["actors"], p["nodes"]) == (1, 1), p
        cluster.add_worker(cpus=1)  # a node joins: auto grows the pool onto it
        p = wait_until(lambda: (q := progress())["nodes"] == 2 and q, 300, "the pool to grow")
        assert p["actors"] == 2 and "node_joined" in events()
        train.send_signal(signal.SIGINT)  # finish the iteration, checkpoint, stop
        assert train.wait(timeout=300) == 0, _tail(tmp_path)
    finally:
        client.close()
        if train.poll() is None:
            train.kill()
            train.wait()
        log.close()


def _tail(tmp_path: Path) -> str:
    return (tmp_path / "train.log").read_text()[-3000:]
