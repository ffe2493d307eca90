"""`paramimic play RUN_DIR`: a run's deterministic policy in MuJoCo in real time, in the browser.

One simulation thread steps the env at the control rate (30 Hz) with the policy's mean action and
renders every step offscreen (MUJOCO_GL=egl); the page shows the frames as an MJPEG stream and
has a slider per task parameter: a shape slider changes the body on the fly ([WL19] §5.2,
`set_shape`; the body follows the slider at up to SHAPE_RATE per second), a goal slider the goal
(`set_goal`); an [L21] run's page sets the task and
"performs" the skill m_a = P_θ(a) from a reset. The loop never drops a control step: on a
machine that cannot keep 30 Hz it runs slower than real time, and says so (real-time factor).
"""

from __future__ import annotations

import io
import secrets
import threading
import time
from contextlib import asynccontextmanager
from pathlib import Path

import numpy as np
from fastapi import FastAPI, HTTPException, Request
from fastapi.responses import FileResponse, JSONResponse, RedirectResponse, StreamingResponse
from pydantic import BaseModel
from starlette.middleware.trustedhost import TrustedHostMiddleware

from paramimic.config import TASK_GOALS, ExperimentConfig
from services.asgi import BodyLimit

STATIC = Path(__file__).resolve().parent / "api" / "static"
STEER = 0.15  # rad per arrow key press (3D bodies: the target direction)
RESTART_AFTER = 1.0  # seconds a fallen body stays down before the episode restarts
# How fast the body follows a shape slider (shape units per second, each parameter): the Fig. 2a
# humanoid walks through its legs changing 0.19/s and falls on half the starts at 0.38/s
# (`benchmarks/humanoid_families.py morph`), so a quick drag of the slider does not fell it.
SHAPE_RATE = 0.15
MAX_BODY = 4096  # bytes: the largest request (a task's values) is well under 1 KB
COOKIE = "paramimic_play"
FREE, TRACKING = 0, 1  # mujoco.mjtCamera: a fixed view, or one that follows the root


class Session:
    """The simulation: env, policy, camera and what the page reads, behind one lock."""

    def __init__(self, cfg: ExperimentConfig, policy, state: dict, width: int = 480,
                 height: int = 360) -> None:  # fmt: skip
        from paramimic.curriculum.marginal_value import MarginalValue
        from paramimic.envs import env_for
        from paramimic.render import Camera
        from paramimic.task_space import TaskSpace
        from paramimic.training.method import method_for

        self.cfg = cfg
        self.env = env_for(cfg)
        self.space: TaskSpace = self.env.task_space
        self.act = policy.numpy_policy()
        self.camera = Camera(width, height)
        method = method_for(cfg)
        self.kind = method.play_kind
        self.marginal = MarginalValue(self.space, cfg.curriculum.marginal_hidden)
        self.marginal.from_state(state["marginal"])
        self.perform = method.performer(state)  # [L21]: m_a = P_θ(a) for "perform"
        self.shape_names = {n for n, _ in self.env._shape_idx}
        self.units = {p["name"]: p["unit"] for p in cfg.parameters()}
        self.lock = threading.Lock()
        self.frame_ready = threading.Condition()
        self.jpeg, self.frame_id = b"", 0
        self.paused, self.follow = False, True
        self.task = self.space.center.copy()
        self.reward_terms: dict = {}
        self.speed = self.rtf = 0.0
        self.fell_at: float | None = None
        self.stop = threading.Event()
        self.reset()

    # --- controls ---------------------------------------------------------------------------

    def reset(self, task: np.ndarray | None = None) -> None:
        with self.lock:
            if task is not None:
                self.task = np.asarray(task, dtype=np.float64)
            options = {"task": self.task}
            motions = None if self.perform is None else self.perform(self.task[None])
            if motions is not None:
                options["motion"] = motions[0]
            self.obs, _ = self.env.reset(seed=int(time.time()), options=options)
            self.fell_at = None

    def set(self, values: dict[str, float]) -> None:
        """New values of task parameters, checked against the task space: a shape parameter
        changes the body in place; a [WL19] goal changes at once, an [L21] one (jump height,
        gravity) at the next `perform`."""
        names = list(self.space.names)
        for name, value in values.items():
            if name not in names:
                raise ValueError(f"{name!r} is not a task parameter; parameters: {names}")
            lo, hi = self.space.low[names.index(name)], self.space.high[names.index(name)]
            if not lo <= value <= hi:
                raise ValueError(f"{name} = {value} is outside its range [{lo:g}, {hi:g}]")
        with self.lock:
            for name, value in values.items():
                self.task[names.index(name)] = value
            # a shape parameter: the body follows it on the fly from the next step on ([WL19]
            # §5.2), in both kinds of run
            if self.kind == "skill":  # [L21] goals and conditions act at the next `perform`
                return
            for name, value in values.items():
                if name in TASK_GOALS:
                    self.obs = self.env.set_goal(name, value)

    def steer(self, delta: float) -> None:
        if "target_direction" not in self.space.names:
            raise ValueError("this run's task has no target_direction to steer")
        i = list(self.space.names).index("target_direction")
        value = float(np.clip(self.task[i] + delta, self.space.low[i], self.space.high[i]))
        self.set({"target_direction": value})

    # --- the loop -------------------------------------------------------------------------

    def run(self) -> None:
        dt = self.env.dt
        next_tick, sim_t, wall_t0 = time.perf_counter(), 0.0, time.perf_counter()
        while not self.stop.is_set():
            if not self.paused:
                self._step()
                sim_t += dt
            self._render()
            next_tick += dt
            wait = next_tick - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            else:  # behind: slow down smoothly, never skip a control step
                next_tick = time.perf_counter()
            wall = time.perf_counter() - wall_t0
            if wall > 2.0:  # the real-time factor over the last ~2 s
                self.rtf = sim_t / wall if not self.paused else 0.0
                sim_t, wall_t0 = 0.0, time.perf_counter()

    def _step(self) -> None:
        with self.lock:
            if self.fell_at is not None:
                if time.perf_counter() - self.fell_at > RESTART_AFTER:
                    self.lock.release()
                    try:
                        self.reset()
                    finally:
                        self.lock.acquire()
                return
            self._follow_shape()
            action = self.act.act(self.obs[None].astype(np.float32), None)[0][0]
            self.obs, _, terminated, truncated, info = self.env.step(action)
            self.reward_terms = {k: float(v) for k, v in info.get("reward_terms", {}).items()}
            self.speed = float(self.env.data.qvel[0])
            if terminated or truncated:
                self.fell_at = time.perf_counter()

    def _follow_shape(self) -> None:
        """Move the body one control step toward the sliders' shape, at SHAPE_RATE at most."""
        now, names = self.env.task, self.space.names
        limit = SHAPE_RATE * self.env.dt
        shape = {}
        for name in self.shape_names:
            i = names.index(name)
            gap = self.task[i] - now[i]
            if gap != 0:
                near = abs(gap) <= limit
                shape[name] = float(self.task[i] if near else now[i] + np.sign(gap) * limit)
        if shape:
            self.obs = self.env.set_shape(shape)

    def _render(self) -> None:
        from PIL import Image

        with self.lock:
            self.camera.camera.type = TRACKING if self.follow else FREE
            pixels = self.camera.frame(self.env)
        buf = io.BytesIO()
        Image.fromarray(pixels).save(buf, format="JPEG", quality=80)
        with self.frame_ready:
            self.jpeg, self.frame_id = buf.getvalue(), self.frame_id + 1
            self.frame_ready.notify_all()

    def frames(self):
        """MJPEG parts, one per new frame."""
        last = -1
        while not self.stop.is_set():
            with self.frame_ready:
                self.frame_ready.wait_for(lambda seen=last: self.frame_id != seen, timeout=1.0)
                jpeg, last = self.jpeg, self.frame_id
            yield b"--frame\r\nContent-Type: image/jpeg\r\n\r\n" + jpeg + b"\r\n"

    def state(self) -> dict:
        with self.lock:
            task = self.space.to_dict(self.task)
            vbar = float(self.marginal.predict(self.task)[0]) if self.marginal.fitted else None
            body = self.env.character
            now = self.space.to_dict(self.env.task)
            return {
                "run": self.cfg.name, "character": self.cfg.character,
                "kind": self.kind,
                "task": task, "ranges": self.space.ranges(),
                "shape_params": sorted(self.shape_names),
                "goals": [n for n in self.space.names if n not in self.shape_names],
                "units": self.units,
                "body": {"hip_height": float(body.hip_height),
                         "mass": float(self.env.model.body_mass.sum()),
                         "shape": {n: now[n] for n in sorted(self.shape_names)}},
                "paused": self.paused, "follow": self.follow, "fallen": self.fell_at is not None,
                "reward_terms": self.reward_terms, "speed": self.speed, "vbar": vbar,
                "mu": self.marginal.mu, "real_time_factor": self.rtf, "frame": self.frame_id,
                "sim_time": float(self.env.data.time),
            }  # fmt: skip


class Values(BaseModel):
    values: dict[str, float]


class Flag(BaseModel):
    on: bool


class Steer(BaseModel):
    delta: float


def create_app(session: Session, token: str) -> FastAPI:
    """The page and its endpoints. Every request carries the session's `token`: the address
    `paramimic play` prints has it (`/?token=...`), which sets it as a same-site cookie, so
    another user or process on the machine cannot watch or drive the session (as Jupyter does)."""

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        session.stop.set()  # ends the MJPEG streams, so that shutdown does not wait for them

    app = FastAPI(title="paramimic play", lifespan=lifespan, docs_url=None, redoc_url=None)
    # loopback only, and a Host header of loopback only: a web page elsewhere cannot drive it
    # by rebinding its own name to 127.0.0.1
    app.add_middleware(TrustedHostMiddleware, allowed_hosts=["127.0.0.1", "localhost", "::1"])
    app.add_middleware(BodyLimit, limit=MAX_BODY)

    @app.middleware("http")
    async def session_token(request: Request, call_next):
        given = request.query_params.get("token")
        if request.url.path == "/" and given is not None and secrets.compare_digest(given, token):
            response = RedirectResponse("/", status_code=303)  # the token leaves the address bar
            response.set_cookie(COOKIE, token, httponly=True, samesite="strict")
            return response
        if secrets.compare_digest(request.cookies.get(COOKIE, ""), token):
            return await call_next(request)
        return JSONResponse(
            {"detail": "open the address `paramimic play` printed: it carries this session's "
                       "token"},
            status_code=401,
        )  # fmt: skip

    def checked(f, *args):
        try:
            f(*args)
        except ValueError as e:
            raise HTTPException(422, str(e)) from None
        return session.state()

    @app.get("/", include_in_schema=False)
    def page() -> FileResponse:
        return FileResponse(STATIC / "play.html", media_type="text/html")

    @app.get("/static/play.js", include_in_schema=False)
    def script() -> FileResponse:
        return FileResponse(STATIC / "play.js", media_type="text/javascript")

    @app.get("/static/common.js", include_in_schema=False)
    def common() -> FileResponse:
        return FileResponse(STATIC / "common.js", media_type="text/javascript")

    @app.get("/static/dashboard.css", include_in_schema=False)
    def style() -> FileResponse:
        return FileResponse(STATIC / "dashboard.css", media_type="text/css")

    @app.get("/stream")
    def stream() -> StreamingResponse:
        return StreamingResponse(
            session.frames(), media_type="multipart/x-mixed-replace; boundary=frame"
        )

    @app.get("/state")
    def state() -> dict:
        return session.state()

    @app.post("/task")
    def task(body: Values) -> dict:
        return checked(session.set, body.values)

    @app.post("/perform")
    def perform(body: Values) -> dict:
        def go(values):
            session.set(values)
            session.reset(session.task)

        return checked(go, body.values)

    @app.post("/reset")
    def reset() -> dict:
        return checked(session.reset)

    @app.post("/pause")
    def pause(body: Flag) -> dict:
        session.paused = body.on
        return session.state()

    @app.post("/follow")
    def follow(body: Flag) -> dict:
        session.follow = body.on
        return session.state()

    @app.post("/steer")
    def steer(body: Steer) -> dict:
        return checked(session.steer, body.delta)

    return app


def serve(cfg: ExperimentConfig, policy, state: dict, host: str, port: int, token: str) -> None:
    import uvicorn

    session = Session(cfg, policy, state)
    loop = threading.Thread(target=session.run, name="play-sim", daemon=True)
    loop.start()
    try:
        uvicorn.run(
            create_app(session, token), host=host, port=port, log_level="warning",
            timeout_graceful_shutdown=3,  # open streams are closed after that
        )  # fmt: skip
    finally:
        session.stop.set()
