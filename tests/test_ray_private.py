"""A laptop run starts a Ray cluster of its own: never the one that Ray's temp dir names
(`ray_current_cluster`, in a directory Ray makes world-writable), which would let anyone on
the machine receive the run's actors, its Redis password and what the driver unpickles."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path


def test_a_laptop_run_ignores_the_cluster_rays_temp_dir_names():
    """A bogus address planted in `ray_current_cluster` (Ray would try to join it and hang);
    `connect(None)` starts a private cluster instead, says so, and runs a task on it."""
    with tempfile.TemporaryDirectory(prefix="ray", dir="/tmp") as short:  # socket paths are short
        _planted(Path(short))


def _planted(temp: Path) -> None:
    (temp / "ray").mkdir(parents=True)
    (temp / "ray" / "ray_current_cluster").write_text("127.0.0.1:9")  # nothing listens
    code = textwrap.dedent(
        """
        import ray
        from services.learner.cluster import connect
        print("started here:", connect(None))
        print("task:", ray.get(ray.remote(lambda: 41 + 1).remote()))
        print("gcs:", ray.get_runtime_context().gcs_address)
        ray.shutdown()
        """
    )
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"} | {"RAY_TMPDIR": str(temp)}
    res = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=180
    )
    assert res.returncode == 0, res.stdout + res.stderr
    assert "started here: True" in res.stdout and "task: 42" in res.stdout
    assert "gcs: 127.0.0.1:9" not in res.stdout
