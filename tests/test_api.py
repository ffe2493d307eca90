"""The progress API: a real uvicorn (`paramimic api`) on loopback over a real Redis holding a run
written by the real reporter and sampler service; schemathesis over its OpenAPI schema."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx
import numpy as np
import pytest
from conftest import API_TOKEN as TOKEN

from paramimic.config import ExperimentConfig
from paramimic.messages import EpisodeReport
from services.launch.api_process import ApiProcess
from services.launch.processes import free_port
from services.learner.reporter import RunReporter
from services.sampler.service import SamplerService

CFG = {
    "name": "api-test",
    "character": "hopper",
    "task": {"leg_length": [0.8, 1.2], "torso_length": [0.9, 1.1], "target_velocity": [1, 1]},
    "curriculum": {"n_mcmc": 50},
}


@pytest.fixture(scope="module")
def api(api_url):
    return api_url


@pytest.fixture(scope="module")
def api_without_token(redis_server, tmp_path_factory):
    api = ApiProcess(
        redis_server.url, "127.0.0.1", free_port(), None, tmp_path_factory.mktemp("api") / "log"
    )
    api.start()
    yield api.url
    api.stop()


@pytest.fixture(scope="module")
def run(redis_server, tmp_path_factory):
    """A run as the learner and the sampler write it: 3 iterations, V̄, tasks, episodes."""
    cfg = ExperimentConfig.model_validate(CFG)
    run_id = "api-test-run"
    reporter = RunReporter(redis_server.url, run_id)
    reporter.start(cfg, tmp_path_factory.mktemp("run"), 3000, None)
    sampler = SamplerService(cfg.model_dump(mode="json"), redis_server.url, run_id)
    rng = np.random.default_rng(0)
    layers = [(rng.normal(size=(3, 8)), rng.normal(size=8)), (rng.normal(size=(8, 1)), [4.0])]
    for it in range(1, 4):
        sampler.next_tasks(4, f"actor{it % 2}")
        sampler.update_marginal(layers, 4.0, it, refill=True)
        sampler.ingest(
            [
                EpisodeReport(f"e{it}-{j}", np.ones(3), 10.0 * it, 30, j == 0, False, {}, j == 0)
                for j in range(2)
            ]
        )
        reporter.progress(
            {
                "iteration": it,
                "env_steps": 1000 * it,
                "episodes_total": 2 * it,
                "steps_per_second": 2500.0,
                "mean_return": 10.0 * it,
                "fall_percent": 50.0,
                "policy_loss": float("nan"),
            }  # fmt: skip
        )
    reporter.event("checkpoint", "checkpoint at iteration 3", {"path": "x"})
    return run_id


def test_every_read_endpoint(api, run):
    with httpx.Client(base_url=api) as c:
        assert c.get("/health").json() == {"status": "ok", "redis": "ok"}
        runs = c.get("/runs").json()
        mine = next(r for r in runs if r["run_id"] == run)
        assert mine["status"] == "running" and mine["iteration"] == 3
        p = c.get(f"/runs/{run}/progress").json()
        assert (p["iteration"], p["env_steps"], p["episodes"], p["total_steps"]) == (
            3,
            3000,
            6,
            3000,
        )
        assert p["mean_return"] == 30.0 and p["fall_percent"] == 50.0
        ch = c.get(f"/runs/{run}/character").json()  # from the registry, via the learner
        assert ch["name"] == "hopper" and ch["planar"] and not ch["swims"] and ch["gait"]
        assert ch["shape_params"]["leg_length"] == [0.5, 1.5]
        assert ch["clips"] == ["planar_jump"] and "paramimic/Hopper-v0" in ch["envs"]

        h = c.get(f"/runs/{run}/history").json()
        assert [x["iteration"] for x in h["items"]] == [1, 2, 3] and h["next_since"] == 3
        assert h["items"][0]["policy_loss"] is None  # NaN is stored as null
        assert [x["iteration"] for x in c.get(f"/runs/{run}/history?since=1").json()["items"]] == [
            2,
            3,
        ]
        assert c.get(f"/runs/{run}/history?since=3").json()["items"] == []

        cur = c.get(f"/runs/{run}/curriculum").json()
        assert cur["mode"] == "adaptive" and cur["k"] == 10.0 and cur["mu"] == 4.0
        assert cur["refills"] == 3 and cur["buffer_adaptive"] and cur["buffer_size"] == 50
        assert cur["episodes"] == 6 and cur["tasks_served"] == 12 and not cur["paused"]
        assert cur["phase"] is None  # no [L21] phase on a [WL19] run

        g = c.get(f"/runs/{run}/curriculum/marginal-value").json()
        assert g["available"] and g["dims"] == ["leg_length", "torso_length"]
        assert len(g["xs"]) == len(g["ys"]) == 21 and len(g["values"]) == 21
        assert len(g["values"][0]) == 21 and g["iteration"] == 3

        s = c.get(f"/runs/{run}/curriculum/samples?limit=2").json()
        assert len(s) == 2 and s[0]["source"] == "actor1" and len(s[0]["tasks"]) == 4
        assert s[0]["names"] == ["leg_length", "torso_length", "target_velocity"]

        ev = c.get(f"/runs/{run}/events").json()
        kinds = [e["type"] for e in ev]
        assert (
            kinds[0] == "run_started" and "sampler_started" in kinds and kinds[-1] == "checkpoint"
        )
        after = c.get(f"/runs/{run}/events", params={"since": ev[-2]["id"]}).json()
        assert [e["type"] for e in after] == ["checkpoint"]
        assert c.get("/docs").status_code == 404  # no CDN scripts beside the dashboard's token
        assert "/runs/{run}/curriculum/marginal-value" in c.get("/openapi.json").json()["paths"]


@pytest.mark.parametrize(
    ("path", "code", "words"),
    [
        ("/runs/nope/progress", 404, "no run 'nope'"),
        ("/runs/nope/curriculum", 404, "no run"),
        ("/runs/nope/events", 404, "no run"),
        ("/runs/nope/character", 404, "no run"),
        ("/runs/bad%20id!/progress", 422, "pattern"),
        ("/runs/{run}/history?since=-1", 422, "greater than or equal"),
        ("/runs/{run}/history?since=abc", 422, "integer"),
        ("/runs/{run}/curriculum/samples?limit=0", 422, "greater than or equal"),
        ("/runs/{run}/events?since=x-1", 422, "pattern"),
        ("/runs/{run}/events?limit=100000", 422, "less than or equal"),
    ],
)
def test_bad_requests_get_4xx_with_a_message(api, run, path, code, words):
    r = httpx.get(api + path.format(run=run))
    assert r.status_code == code
    assert words in str(r.json()["detail"])


def test_changing_a_run_needs_the_token(api, api_without_token, run, redis_server):
    import redis

    with httpx.Client(base_url=api) as c:
        assert c.post(f"/runs/{run}/pause").status_code == 401
        wrong = {"Authorization": "Bearer wrong"}
        assert c.post(f"/runs/{run}/pause", headers=wrong).status_code == 401
        auth = {"Authorization": f"Bearer {TOKEN}"}
        assert c.post(f"/runs/{run}/pause", headers=auth).status_code == 202
        assert c.get(f"/runs/{run}/curriculum").json()["paused"]
        r = c.put(f"/runs/{run}/curriculum/k", json={"k": 3.5}, headers=auth)
        assert r.status_code == 202 and r.json()["requested"] == {"k": 3.5}
        assert c.put(f"/runs/{run}/curriculum/k", json={"k": -1}, headers=auth).status_code == 422
        assert c.put(f"/runs/{run}/curriculum/k", json={}, headers=auth).status_code == 422
        assert c.post("/runs/nope/pause", headers=auth).status_code == 404
        assert c.post(f"/runs/{run}/resume", headers=auth).status_code == 202
        kinds = [e["type"] for e in c.get(f"/runs/{run}/events").json()]
        assert kinds[-3:] == ["pause_requested", "k_requested", "resume_requested"]
    control = redis.Redis.from_url(redis_server.url, decode_responses=True).hgetall(
        f"paramimic:run:{run}:control"
    )
    assert control == {"paused": "0", "k": "3.5"}
    r = httpx.post(f"{api_without_token}/runs/{run}/pause", headers=auth)
    assert r.status_code == 403 and "disabled" in r.json()["detail"]


def test_skill_endpoints(api, run, skill_run):
    with httpx.Client(base_url=api) as c:
        cur = c.get(f"/runs/{skill_run}/curriculum").json()
        assert cur["mode"] == "uniform" and cur["phase"] == "uniform" and cur["stage"] == "proxy"
        assert cur["elites"] >= 3 and cur["episodes"] >= cur["elites"]
        assert cur["task_ranges"] == {"gravity": [0.5, 1.5], "jump_height": [0.0, 0.6]}
        every = c.get(f"/runs/{skill_run}/curriculum/elites").json()
        assert every["names"] == ["gravity", "jump_height"]
        assert len(every["items"]) == every["total"] == cur["elites"]
        assert all(0.1 < e["fitness"] <= 1.1 for e in every["items"])
        g = [e["params"]["gravity"] for e in every["items"]]
        box = c.get(
            f"/runs/{skill_run}/curriculum/elites", params={"low": "0.5,0", "high": "1.0,0.6"}
        ).json()
        assert len(box["items"]) == sum(x <= 1.0 for x in g)
        near = c.get(
            f"/runs/{skill_run}/curriculum/elites", params={"near": "1.0,0.1", "k": 2}
        ).json()
        assert len(near["items"]) == 2
        d = [e["distance"] for e in near["items"]]
        brute = sorted(
            np.hypot(e["params"]["gravity"] - 1.0, (e["params"]["jump_height"] - 0.1) / 0.6)
            for e in every["items"]
        )
        assert d == pytest.approx(brute[:2])
        for bad in ({"near": "1.0"}, {"near": "a,b"}, {"low": "1,2,3"}, {"near": "nan,1"}):
            r = c.get(f"/runs/{skill_run}/curriculum/elites", params=bad)
            assert r.status_code == 422 and "comma-separated" in r.json()["detail"]
        dens = c.get(f"/runs/{skill_run}/curriculum/density").json()
        assert dens["available"] and dens["dims"] == ["gravity", "jump_height"]
        assert len(dens["values"]) == 21 and max(map(max, dens["values"])) > 0.5
        assert dens["visited"] == 0.8 and dens["surrounding"] == 0.2
        for path in ("elites", "density"):  # a [WL19] run has neither
            r = c.get(f"/runs/{run}/curriculum/{path}")
            assert r.status_code == 404 and "no [L21] skill curriculum" in r.json()["detail"]


def test_a_run_lists_its_parameters_by_name_unit_and_measure(api, run, skill_run, redis_server,
                                                              tmp_path):  # fmt: skip
    """GET /runs/{run} names every task parameter with its unit and meaning."""
    with httpx.Client(base_url=api) as c:
        wl19 = c.get(f"/runs/{run}").json()
        assert wl19["name"] == "api-test" and wl19["config"]["character"] == "hopper"
        kinds = {p["name"]: (p["kind"], p["unit"], p["constraint"]) for p in wl19["parameters"]}
        assert kinds == {"leg_length": ("shape", "x base", False),
                         "torso_length": ("shape", "x base", False),
                         "target_velocity": ("goal", "m/s", True)}  # fmt: skip
        l21 = {p["name"]: p for p in c.get(f"/runs/{skill_run}").json()["parameters"]}
        assert l21["gravity"]["kind"] == "condition" and l21["gravity"]["unit"] == "G"
        jump = l21["jump_height"]  # the built-in name is the COM rise, a spike at the clip's end
        assert (jump["measure"], jump["unit"], jump["reward"], jump["event"]) == (
            "com_rise", "m", "spike", "clip_end")  # fmt: skip
        cfg = ExperimentConfig.model_validate({
            "character": "humanoid", "env": {"clip": "humanoid_backflip"},
            "task": {"spin": {"measure": "airborne_angular_velocity", "axis": "pitch",
                              "unit": "reference", "range": [0.5, 2.0]},
                     "turn": {"measure": "root_rotation", "axis": "pitch", "unit": "turns",
                              "range": [1.0, 1.0]}},
        })  # fmt: skip
        RunReporter(redis_server.url, "declared-run").start(cfg, tmp_path, 10, None)
        declared = {p["name"]: p for p in c.get("/runs/declared-run").json()["parameters"]}
        spin, turn = declared["spin"], declared["turn"]
        assert (spin["measure"], spin["axis"], spin["unit"], spin["constraint"]) == (
            "airborne_angular_velocity", "pitch", "reference", False)  # fmt: skip
        assert (turn["unit"], turn["constraint"], turn["range"]) == ("turns", True, [1.0, 1.0])
        r = c.get("/runs/no-such-run")
        assert r.status_code == 404


def test_a_finished_run_cannot_be_paused(api, redis_server, tmp_path):
    cfg = ExperimentConfig.model_validate(CFG)
    reporter = RunReporter(redis_server.url, "finished-run")
    reporter.start(cfg, tmp_path, 10, None)
    reporter.set_status("finished", "done")
    r = httpx.post(f"{api}/runs/finished-run/pause", headers={"Authorization": f"Bearer {TOKEN}"})
    assert r.status_code == 409 and "finished" in r.json()["detail"]


@pytest.mark.parametrize(
    "fixed_run", ["wl19", "l21", None], ids=["known-run", "skill-run", "any-run"]
)
def test_schemathesis_finds_no_server_error(api, run, skill_run, tmp_path, fixed_run):
    """Property-based requests over the whole OpenAPI schema, with the token: no 5xx. With a
    known run every {run} is a seeded run, so the requests reach the endpoints' logic."""
    config = tmp_path / "schemathesis.toml"
    known = {"wl19": run, "l21": skill_run}.get(fixed_run)
    config.write_text(f'[parameters]\nrun = "{known}"\n' if known else "")
    exe = Path(sys.executable).parent / "schemathesis"
    res = subprocess.run(
        [
            exe,
            "--config-file",
            config,
            "run",
            f"{api}/openapi.json",
            "--checks",
            "not_a_server_error",
            "--max-examples",
            "40",
            "-H",
            f"Authorization: Bearer {TOKEN}",
            "--workers",
            "1",
            "--seed",
            "1",
        ],  # fmt: skip
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,  # its cache goes there, not into the checkout
    )
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]
    if fixed_run == "l21":
        assert "Missing test data" not in res.stdout, res.stdout[-3000:]
    elif fixed_run == "wl19":  # only the [L21] endpoints answer 404 for a [WL19] run
        missing = {
            line.strip() for line in res.stdout.splitlines() if line.strip().startswith("- ")
        }
        assert missing <= {
            "- GET /runs/{run}/curriculum/elites",
            "- GET /runs/{run}/curriculum/density",
        }, res.stdout[-3000:]


def test_the_api_imports_neither_torch_nor_mujoco_nor_ray():
    code = (
        "import sys, services.api.app, services.cli; "
        "bad = {'torch', 'mujoco', 'ray'} & set(sys.modules); assert not bad, bad"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


def test_a_foreign_host_header_and_a_nan_body_get_4xx(api_url, redis_server, tmp_path):
    """DNS rebinding: a request naming another host is refused before any route runs; a JSON
    body holding NaN gets 422 with the NaN echoed as null (not 500)."""
    from conftest import API_TOKEN

    from services.learner.reporter import RunReporter

    RunReporter(redis_server.url, "host-check").start(
        ExperimentConfig.model_validate({"character": "hopper"}), tmp_path, 10, None
    )
    with httpx.Client(base_url=api_url, timeout=10.0) as c:
        assert c.get("/runs").status_code == 200
        assert c.get("/runs", headers={"Host": "evil.example:8000"}).status_code == 400
        auth = {"Content-Type": "application/json", "Authorization": f"Bearer {API_TOKEN}"}
        # the only JSON body the API takes; schemathesis cannot send these (not JSON)
        for bad in ("NaN", "Infinity", "-Infinity", "1e999"):
            res = c.put("/runs/host-check/curriculum/k", content=f'{{"k": {bad}}}', headers=auth)
            assert res.status_code == 422, (bad, res.text)
            assert res.json()["detail"][0]["input"] is None, bad
