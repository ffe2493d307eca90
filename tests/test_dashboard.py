"""The dashboard in a real browser: headless Chromium (Debian's `chromium` and `chromium-driver`,
driven by Selenium) on the real API, over a real training job and a real [L21] run. Installs
Chromium with apt where it can (root); skips with the reason elsewhere. Screenshots
(dashboard_runs.png, dashboard_run.png, dashboard_skill.png) go where the `screenshots` fixture
says."""

from __future__ import annotations

import os
import subprocess
import sys

import httpx
import pytest
import yaml
from conftest import API_TOKEN, holds, wait_until

TINY = {
    "name": "dash",
    "character": "hopper",
    "task": {"leg_length": [0.8, 1.2], "torso_length": [0.9, 1.1], "target_velocity": [1, 1]},
    "env": {"max_episode_seconds": 1.0},
    "ppo": {"num_steps": 256, "minibatch_size": 64, "num_epochs": 2},
    "curriculum": {"p_mcmc": 1, "n_mcmc": 100},
    "actors": {"num_actors": 1, "num_envs": 4},
    "train": {"total_steps": 10**9, "checkpoint_every": 5},
}


@pytest.fixture(scope="module")
def job(redis_server, tmp_path_factory):
    """A real training job (local Ray, one actor) on the session's Redis, no API of its own:
    the session API serves its dashboard."""
    tmp = tmp_path_factory.mktemp("dash")
    cfg = tmp / "dash.yaml"
    cfg.write_text(yaml.safe_dump(TINY))
    env = os.environ | {"REDIS_URL": redis_server.url, "RAY_ADDRESS": "", "COLUMNS": "200"}
    log = (tmp / "train.log").open("w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "services.cli", "train", cfg, "--run-dir", tmp / "run", "--no-api"],
        stdout=log, stderr=subprocess.STDOUT, env=env,
    )  # fmt: skip
    run_file = tmp / "run" / "run_id"
    wait_until(lambda: run_file.exists() and proc.poll() is None, 180, "the run to start")
    yield run_file.read_text().strip()
    proc.send_signal(2)
    try:
        proc.wait(120)
    except subprocess.TimeoutExpired:
        proc.kill()


def _js(browser, script: str):
    return browser.execute_script(script)


def _points(browser, div: str, trace: int = 0, axis: str = "x") -> int:
    script = (
        f"const d = document.getElementById('{div}'), t = d && d.data && d.data[{trace}];"
        f"return t ? (t.{axis} || []).length : 0;"
    )
    return _js(browser, script)


def _iteration(api: httpx.Client, run: str) -> int:
    r = api.get(f"/runs/{run}/progress")
    return r.json()["iteration"] if r.status_code == 200 else -1


def test_runs_page_and_a_live_run_page_with_pause(browser, api_url, job, screenshots):
    api = httpx.Client(base_url=api_url, timeout=10)
    wait_until(lambda: _iteration(api, job) >= 3, 180, "3 iterations")
    browser.get(f"{api_url}/")
    wait_until(lambda: _js(browser, f"return !!document.querySelector('tr[data-run=\"{job}\"]')"),
               30, "the run in the runs table")  # fmt: skip
    row = _js(browser, f"return document.querySelector('tr[data-run=\"{job}\"]').innerText")
    assert "running" in row and "hopper" in row
    browser.save_screenshot(str(screenshots / "dashboard_runs.png"))

    browser.get(f"{api_url}/ui/runs/{job}")
    wait_until(lambda: _points(browser, "curve-mean_return") >= 3, 60, "curve points")
    for key in ("fall_percent", "mean_length", "steps_per_second", "std", "approx_kl"):
        assert _points(browser, f"curve-{key}") >= 3, key
    grid = api.get(f"/runs/{job}/curriculum/marginal-value").json()
    wait_until(lambda: _points(browser, "task-map", 0, "z") == len(grid["values"]), 60, "V̄ map")
    cells = _js(browser, "return document.getElementById('task-map').data[0].z.flat().length")
    assert cells == len(grid["values"]) * len(grid["values"][0]) == 21 * 21
    assert _points(browser, "task-map", 2) > 0  # the recent task samples over it
    events = "return document.querySelectorAll('#events [data-type]').length"
    wait_until(lambda: _js(browser, events) > 0, 60, "the events list")  # its own poll
    browser.save_screenshot(str(screenshots / "dashboard_run.png"))

    # pause from the page (the token typed in, sent as a bearer token): progress stops
    _js(browser, f"document.getElementById('token').value = '{API_TOKEN}';"
                 "document.getElementById('pause').click();")  # fmt: skip
    wait_until(lambda: api.get(f"/runs/{job}/progress").json()["status"] == "paused", 120, "pause")
    held = api.get(f"/runs/{job}/progress").json()["iteration"]
    holds(lambda: api.get(f"/runs/{job}/progress").json()["iteration"] == held, 3.0, "pause")
    status = "return document.getElementById('run-status').innerText"
    wait_until(lambda: "paused" in _js(browser, status), 30, "the page to say paused")
    _js(browser, "document.getElementById('resume').click();")
    wait_until(lambda: api.get(f"/runs/{job}/progress").json()["iteration"] > held, 120, "resume")


def test_a_skill_run_page_shows_every_elite_and_the_density(
    browser, api_url, skill_run, screenshots
):
    elites = httpx.get(f"{api_url}/runs/{skill_run}/curriculum/elites?limit=100000").json()
    browser.get(f"{api_url}/ui/runs/{skill_run}")
    density = httpx.get(f"{api_url}/runs/{skill_run}/curriculum/density").json()
    n_traces = 3 + 1 if density["available"] else 1  # density, A_h, A_s, elites
    wait_until(lambda: _js(browser, "const d = document.getElementById('task-map');"
                                    "return d && d.data ? d.data.length : 0") == n_traces,
               60, "the elite scatter")  # fmt: skip
    assert _points(browser, "task-map", n_traces - 1) == elites["total"] >= 3
    # the task parameters by name, unit and measure, with the latest a'
    rows = _js(browser, "return [...document.querySelectorAll('#parameters tr[data-name]')]"
                        ".map(r => r.innerText)")  # fmt: skip
    assert rows[0].startswith("gravity") and "G" in rows[0]
    assert "com_rise" in rows[1] and "m\t" in rows[1] and "spike at clip_end" in rows[1]
    wait_until(lambda: "[" in _js(browser, "return document.querySelector("
                                           "'#parameters tr[data-name=jump_height]').innerText"),
               30, "the latest a'")  # fmt: skip
    title = "return document.getElementById('task-map').layout.yaxis.title.text"
    assert _js(browser, title) == "jump_height (m)"
    browser.save_screenshot(str(screenshots / "dashboard_skill.png"))


def test_the_plotly_bundle_is_served_from_the_wheel(api_url):
    r = httpx.get(f"{api_url}/static/plotly.min.js")
    assert r.status_code == 200 and len(r.content) > 1_000_000 and b"plotly" in r.content[:2000]
    assert httpx.get(f"{api_url}/static/nope.js").status_code == 404
