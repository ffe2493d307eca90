"""An end-to-end [L21] run on a real local Ray with the sampler's state in a real Redis: elites,
their traces, P_θ and the bootstrap stages appear in Redis and through the API (real uvicorn)."""

import json

import httpx
import numpy as np
import ray
import redis

from paramimic.config import ExperimentConfig
from paramimic.training.method import method_for
from services.keys import RunKeys
from services.launch.stack import ray_stack
from services.learner.reporter import RunReporter
from services.sampler.service import SamplerService


def _cfg() -> ExperimentConfig:
    return ExperimentConfig.model_validate(
        {
            "name": "walker-jump-e2e",
            "character": "walker",
            "task": {"gravity": [0.2, 1.65], "jump_height": [0.0, 0.6]},
            "env": {"clip": "planar_jump"},
            "ppo": {"num_steps": 512, "minibatch_size": 128, "num_epochs": 2,
                    "init_log_std": -2.0},
            "curriculum": {
                "display_dims": ["gravity", "jump_height"],
                "skill": {
                    "batch_size": 4,
                    "episodes_per_param": 2,
                    "base_min_iterations": 1,
                    "base_max_iterations": 2,
                    "p_every": 2,
                },
            },
            "actors": {"num_actors": 2, "num_envs": 4},
            "train": {"checkpoint_every": 3, "seed": 3},
        }
    )  # fmt: skip


def test_walker_jump_on_ray_fills_elites_in_redis_and_the_api(
    local_ray, redis_server, run_id, api_url, tmp_path
):
    cfg = _cfg()
    RunReporter(redis_server.url, run_id).start(cfg, tmp_path, 6 * 512, None)
    with ray_stack(cfg, tmp_path, redis_server.url, run_id) as stack:
        metrics = []
        stack.trainer.train(stack.backend, total_steps=6 * 512, on_metrics=metrics.append)
        digest = ray.get(stack.sampler.digest.remote())
        summary = stack.trainer.curriculum.summary()
    # the learner left π0 after base_max_iterations and fitted P_θ on the elites
    assert [m["stage"] for m in metrics][:2] == ["base", "proxy"]
    assert summary.stage in ("proxy", "mixed") and summary.motion_version >= 1
    assert summary.elites > 0 and summary.episodes == stack.trainer.progress.episodes

    r = redis.Redis.from_url(redis_server.url, decode_responses=True)
    keys = RunKeys(run_id)
    elites = json.loads(r.hget(keys.curriculum, "elites"))
    traces = r.hgetall(keys.traces)
    assert set(traces) == set(elites["keys"]) and len(traces) == summary.elites
    shape = np.array(json.loads(next(iter(traces.values())))).shape
    assert shape == (16, 3 + 6 + 1)  # bins x (root x/z/pitch, six joints, τ)
    assert min(elites["fitness"]) > 0.1
    # a sampler started again on the same run reloads exactly this state, traces included
    again = SamplerService(
        cfg.model_dump(mode="json"),
        redis_server.url,
        run_id,
        True,
        clip=method_for(cfg).spaces.clip_setup(),
    )
    assert again.digest() == digest

    with httpx.Client(base_url=api_url) as c:
        cur = c.get(f"/runs/{run_id}/curriculum").json()
        assert cur["mode"] == "skill" and cur["elites"] == summary.elites
        assert cur["phase"] in ("exploration", "refinement")
        assert cur["episodes"] == summary.episodes
        assert cur["reference"]["gravity"] == 1.0
        items = c.get(f"/runs/{run_id}/curriculum/elites").json()["items"]
        assert {e["key"] for e in items} == set(elites["keys"])
        near = c.get(f"/runs/{run_id}/curriculum/elites", params={"near": "1.0,0.1", "k": 1})
        assert len(near.json()["items"]) == 1
        density = c.get(f"/runs/{run_id}/curriculum/density").json()
        assert density["available"] and density["elites"] == summary.elites
        assert max(map(max, density["values"])) > 0.5
        samples = c.get(f"/runs/{run_id}/curriculum/samples").json()
        assert {s["region"] for s in samples} >= {"reference"}
        types = [e["type"] for e in c.get(f"/runs/{run_id}/events").json()]
        assert "stage_changed" in types
