"""`paramimic play` for real: the CLI (MUJOCO_GL unset, as a new user has it) serves a trained
run in MuJoCo at 30 Hz; headless Chromium moves a body slider on the page, the body in the
simulation changes and frames keep coming. Screenshot: play.png (the `screenshots` fixture)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import httpx
import pytest
import yaml
from conftest import wait_until

from services.launch.processes import free_port
from services.play import COOKIE

ROOT = Path(__file__).resolve().parent.parent
TINY = {
    "character": "walker",
    "task": {"left_leg_length": [0.8, 1.2], "right_leg_length": [0.8, 1.2],
             "target_velocity": [0.5, 1.5]},
    "env": {"max_episode_seconds": 2.0},
    "ppo": {"num_steps": 256, "minibatch_size": 128, "num_epochs": 1},
    "actors": {"num_envs": 4},
    "train": {"total_steps": 512, "checkpoint_every": 1},
}  # fmt: skip


def _env() -> dict:
    return {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}


@pytest.fixture(scope="module")
def play_url(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("play")
    cfg = tmp / "tiny.yaml"
    cfg.write_text(yaml.safe_dump(TINY))
    cli = [sys.executable, "-m", "services.cli"]
    res = subprocess.run([*cli, "train", cfg, "--serial", "--run-dir", tmp / "run"],
                         capture_output=True, text=True, timeout=300, env=_env())  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    port = free_port()
    proc = subprocess.Popen(
        [*cli, "play", tmp / "run", "--port", str(port)],
        env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
    url = f"http://127.0.0.1:{port}"

    def printed() -> bool:
        assert proc.poll() is None, "".join(lines)
        return "play: http" in "".join(lines)

    wait_until(printed, 120, "the play address")
    found = re.search(rf"play: http://127\.0\.0\.1:{port}/\?token=([\w-]+)", "".join(lines))
    assert found, "".join(lines)
    token = found.group(1)

    def up() -> bool:
        assert proc.poll() is None, "".join(lines)
        try:
            return httpx.get(f"{url}/state", cookies={COOKIE: token}, timeout=2).status_code == 200
        except httpx.HTTPError:
            return False

    wait_until(up, 120, "the play server")
    yield url, token
    proc.terminate()  # SIGTERM: uvicorn ends, open MJPEG streams included
    proc.wait(30)


def test_a_slider_changes_the_body_and_frames_keep_coming(browser, play_url, screenshots):
    play_url, token = play_url
    http = httpx.Client(cookies={COOKIE: token}, timeout=5)
    state = lambda: http.get(f"{play_url}/state").json()  # noqa: E731
    first = state()
    assert first["kind"] == "family" and first["shape_params"] == [
        "left_leg_length", "right_leg_length"]  # fmt: skip
    wait_until(lambda: state()["frame"] > first["frame"] + 10, 60, "frames")
    browser.get(f"{play_url}/?token={token}")  # the printed address
    wait_until(lambda: browser.execute_script(
        "const v = document.getElementById('view'); return v.complete && v.naturalWidth > 0;"),
        60, "the MJPEG stream in the page")  # fmt: skip
    slider = "return !!document.getElementById('slider-left_leg_length')"
    wait_until(lambda: browser.execute_script(slider), 30, "the sliders")
    before = state()
    browser.execute_script(
        "const s = document.getElementById('slider-left_leg_length');"
        "s.value = 1.2; s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change'));"
    )
    wait_until(lambda: abs(state()["task"]["left_leg_length"] - 1.2) < 1e-6, 30, "the new task")
    # the body follows the slider at SHAPE_RATE: 0.2 in 1.3 s of simulated time
    wait_until(
        lambda: state()["body"]["shape"]["left_leg_length"] == pytest.approx(1.2), 60, "the body"
    )
    after = state()
    assert after["body"]["mass"] != pytest.approx(before["body"]["mass"], rel=1e-6)
    wait_until(lambda: state()["frame"] > after["frame"] + 10, 60, "frames after the change")
    # a goal slider changes the goal; out-of-range values are refused with a message
    r = http.post(f"{play_url}/task", json={"values": {"target_velocity": 1.4}})
    assert r.status_code == 200 and r.json()["task"]["target_velocity"] == pytest.approx(1.4)
    r = http.post(f"{play_url}/task", json={"values": {"left_leg_length": 3.0}})
    assert r.status_code == 422 and "outside its range" in r.json()["detail"]
    browser.save_screenshot(str(screenshots / "play.png"))


def test_a_skill_run_performs_the_chosen_task_and_a_3d_body_steers(tmp_path):
    """[L21]: `perform` resets to the chosen task with m_a = P_θ(a) from the checkpoint's
    curriculum; a 3D character's target direction follows the arrow keys' `steer`."""
    from fastapi.testclient import TestClient

    from paramimic.config import load_config
    from paramimic.training.trainer import SerialBackend, Trainer
    from services.play import SHAPE_RATE, Session, create_app

    LOOPBACK = "http://127.0.0.1"  # play answers loopback Host headers only
    TOKEN = "a-session-token"

    def client_of(session):
        client = TestClient(create_app(session, TOKEN), base_url=LOOPBACK)
        assert client.get(f"/?token={TOKEN}").status_code == 200  # sets the cookie, redirects
        return client

    def trained(config: str, overrides: dict):
        cfg = load_config(ROOT / config, overrides | {"train.run_dir": str(tmp_path / config)})
        trainer = Trainer(cfg, tmp_path / config)
        backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
        trainer.train(backend, 2 * cfg.ppo.num_steps)
        backend.close()
        return cfg, trainer.learner.policy, trainer.state_dict()

    small = {"ppo.num_steps": 256, "ppo.minibatch_size": 128, "actors.num_envs": 4}
    skill = Session(*trained("configs/walker_jump.yaml", small))
    with client_of(skill) as client:
        state = client.get("/state").json()
        assert state["kind"] == "skill" and set(state["task"]) == {"gravity", "jump_height"}
        assert state["goals"] == ["gravity", "jump_height"]  # sliders with their units
        assert state["units"] == {"gravity": "G", "jump_height": "m"}
        r = client.post("/perform", json={"values": {"jump_height": 0.4, "gravity": 0.8}})
        assert r.status_code == 200, r.text
        performed = skill.space.to_dict(skill.env._task)
        assert performed == pytest.approx({"gravity": 0.8, "jump_height": 0.4})
        skill._step()  # the policy acts on the performed task (frames: the browser test)
        assert skill.env.data.time > 0
    skill.stop.set()

    # an [L21] run's body changes on the fly too; its goals wait for `perform`
    body = Session(*trained("configs/hopper_jump_body.yaml", small))
    with client_of(body) as client:
        state = client.get("/state").json()
        name = state["shape_params"][0]
        lo, hi = state["ranges"][name]
        mass = state["body"]["mass"]
        after = client.post("/task", json={"values": {name: hi}}).json()
        assert after["task"][name] == pytest.approx(hi)
        body._step()  # the body follows the slider one step at a time
        after = client.get("/state").json()
        assert after["body"]["mass"] != pytest.approx(mass, rel=1e-6)
        gap = abs(after["body"]["shape"][name] - state["body"]["shape"][name])
        assert 0 < gap <= SHAPE_RATE * body.env.dt + 1e-9
    body.stop.set()

    steer = {"task.target_direction": [-1.0, 1.0], "env.max_episode_seconds": 2.0}
    biped = Session(*trained("configs/biped_lower.yaml", small | steer))
    with client_of(biped) as client:
        before = client.get("/state").json()["task"]["target_direction"]
        after = client.post("/steer", json={"delta": 0.15}).json()["task"]["target_direction"]
        assert after == pytest.approx(before + 0.15)
        assert client.post("/steer", json={"delta": 5.0}).json()["task"][
            "target_direction"] == pytest.approx(1.0)  # clipped to the range  # fmt: skip
    biped.stop.set()


def test_play_answers_loopback_host_headers_only(play_url):
    """DNS rebinding: a page of another site that resolves its own name to 127.0.0.1 gets 400."""
    play_url, token = play_url
    mine = {COOKIE: token}
    assert httpx.get(f"{play_url}/state", cookies=mine, timeout=5).status_code == 200
    foreign = httpx.get(
        f"{play_url}/state", headers={"Host": "evil.example"}, cookies=mine, timeout=5
    )
    assert foreign.status_code == 400


def test_play_wants_its_session_token_and_a_small_body(play_url):
    """Another user or process on the machine cannot watch or drive the session without the
    printed token; the address with it sets the cookie; a body over 4 KB gets 413 unparsed."""
    play_url, token = play_url
    for path in ("/", "/state", "/stream", "/static/play.js"):
        r = httpx.get(f"{play_url}{path}", timeout=5)
        assert r.status_code == 401 and "token" in r.json()["detail"], path
        wrong = httpx.get(f"{play_url}{path}", cookies={COOKIE: "guess"}, timeout=5)
        assert wrong.status_code == 401, path
    assert httpx.get(f"{play_url}/?token=guess", timeout=5).status_code == 401
    r = httpx.post(f"{play_url}/task", json={"values": {"target_velocity": 1.0}}, timeout=5)
    assert r.status_code == 401
    with httpx.Client(base_url=play_url, timeout=5) as c:
        r = c.get(f"/?token={token}", follow_redirects=False)
        assert r.status_code == 303 and r.headers["location"] == "/"
        assert "httponly" in r.headers["set-cookie"].lower()
        assert "samesite=strict" in r.headers["set-cookie"].lower()
        assert c.get("/state").status_code == 200  # the cookie it set
        big = {"values": {"target_velocity": 1.0}, "pad": "x" * 5000}
        r = c.post("/task", json=big)
        assert r.status_code == 413 and "4096 bytes" in r.json()["detail"]


def test_the_fig2a_humanoid_keeps_walking_while_play_sliders_move_its_legs_and_arms():
    """`paramimic play humanoid_fig2a`: the sliders jump (legs 1.0 -> 0.6 and arms -> 1.4, then
    legs -> 1.5) and the walking body follows them at SHAPE_RATE without falling."""
    from paramimic.training import checkpoint
    from services.play import SHAPE_RATE, Session

    state, cfg, policy = checkpoint.load_policy("humanoid_fig2a")
    cfg.env = cfg.env.for_evaluation(30.0)
    session = Session(cfg, policy, state)
    steps = lambda seconds: range(int(round(seconds / session.env.dt)))  # noqa: E731
    for _ in steps(1.0):
        session._step()
    for values in ({"leg_length": 0.6, "arm_length": 1.4}, {"leg_length": 1.5}):
        session.set(values)
        for _ in steps(0.9 / SHAPE_RATE + 1.0):  # the largest change, then a second more
            session._step()
            assert session.fell_at is None, session.state()["body"]
        assert session.state()["body"]["shape"] == pytest.approx(
            {"leg_length": values["leg_length"], "arm_length": 1.4, "height": 1.0, "thickness": 1.0}
        )
    session.stop.set()
