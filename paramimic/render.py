"""Pictures of a parametric controller: one policy on several bodies side by side ([WL19]
Fig. 1, 4), or one body whose shape morphs along a path while it moves (§5.2).

Frames come from MuJoCo's offscreen renderer (`mujoco.Renderer`), which runs on a CPU through
EGL with Mesa's software rasterizer (`MUJOCO_GL=egl`) or OSMesa (`MUJOCO_GL=osmesa`). A camera
tracks each body's root from the side, at a distance that follows the body's size (a morph keeps
one distance, its tallest body's, so that the change shows).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import mujoco
import numpy as np

from paramimic.characters.body import Body
from paramimic.envs.param_env import ParamEnv
from paramimic.evaluation import Act, Motions, morph_episode


class Camera:
    """An offscreen renderer for one environment; rebuilt when the env's model changes (a
    shape change compiles a new model)."""

    def __init__(self, width: int, height: int, distance: float | None = None) -> None:
        self.width, self.height = width, height
        self.fixed_distance = distance  # None: the distance follows each body's size
        self._renderer: mujoco.Renderer | None = None
        self._model: mujoco.MjModel | None = None
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        self.camera.azimuth = 90.0  # looking at the body's left side (+y toward the camera)
        self.camera.elevation = -12.0

    def frame(self, env: ParamEnv) -> np.ndarray:
        """The env's current state as an RGB image [height, width, 3] (uint8)."""
        if env.model is not self._model:
            self.close()
            self._renderer = mujoco.Renderer(env.model, self.height, self.width)
            self._model = env.model
            self.camera.trackbodyid = env.character.root_body_id
            self.camera.distance = self.fixed_distance or camera_distance(env)
        assert self._renderer is not None
        self._renderer.update_scene(env.data, self.camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
            self._model = None


def camera_distance(env: ParamEnv, body: Body | None = None) -> float:
    """How far from its root the camera sees `body` (the env's current one) whole."""
    body = body or env.character
    if env.definition.swims:
        return 2.5 * _body_length(body.model)
    return 1.2 + 3.0 * body.hip_height


def _body_length(model: mujoco.MjModel) -> float:
    """Extent of the body's geoms along x, a swimmer's length."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    x = data.geom_xpos[:, 0]
    return float(x.max() - x.min() + 2 * model.geom_size[:, 0].max())


def label(frame: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """`frame` with `lines` of text in its top-left corner, on a translucent box."""
    from PIL import Image, ImageDraw, ImageFont

    image = Image.fromarray(frame).convert("RGBA")
    size = max(9, frame.shape[0] // 22)
    font = ImageFont.load_default(size=size)
    overlay = Image.new("RGBA", image.size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(overlay)
    width = max((draw.textlength(line, font=font) for line in lines), default=0)
    draw.rectangle([0, 0, width + 8, len(lines) * (size + 2) + 6], fill=(255, 255, 255, 170))
    for k, line in enumerate(lines):
        draw.text((4, 3 + k * (size + 2)), line, fill=(0, 0, 0, 255), font=font)
    return np.asarray(Image.alpha_composite(image, overlay).convert("RGB"))


def shape_label(env: ParamEnv) -> list[str]:
    """The body's non-default task parameters, e.g. ['left_leg_length 0.80', ...]."""
    task = env.task_space.to_dict(env._task)
    names = [n for n, _ in env._shape_idx] or list(task)
    return [f"{n} {task[n]:.2f}" for n in names]


def render_family(
    act: Act,
    make_env: Callable[[], ParamEnv],
    tasks: Sequence[np.ndarray],
    seconds: float,
    width: int = 320,
    height: int = 240,
    seed: int = 0,
    motions: Motions | None = None,
) -> list[np.ndarray]:
    """One policy on each task's body, side by side: frames [height, width·n, 3] at the
    control rate, each panel labelled with its body's shape parameters and its mean forward
    speed so far (a fall says so). A body whose episode ends stays in its last frame.
    `motions`: what each task is performed with ([L21]: m_a = P_θ(a), `Method.performer`)."""
    envs = [make_env() for _ in tasks]
    cams = [Camera(width, height) for _ in tasks]
    dealt = None if motions is None else motions(np.asarray(tasks))
    obs = np.stack(
        [
            e.reset(
                seed=seed + i, options={"task": t} | ({} if dealt is None else {"motion": dealt[i]})
            )[0]
            for i, (e, t) in enumerate(zip(envs, tasks, strict=True))
        ]
    )
    start = [e.data.qpos[0] for e in envs]
    steps = [0] * len(envs)
    done, fell = [False] * len(envs), [False] * len(envs)

    def panel(i: int) -> np.ndarray:
        env, t = envs[i], max(steps[i], 1) * envs[i].dt
        speed = (env.data.qpos[0] - start[i]) / t if steps[i] else 0.0
        status = "fell" if fell[i] else f"speed {speed:.2f} m/s"
        return label(cams[i].frame(env), [*shape_label(env), status])

    last = [panel(i) for i in range(len(envs))]
    frames = [np.concatenate(last, axis=1)]
    for _ in range(int(round(seconds / envs[0].dt))):
        actions = act(obs)
        for i, env in enumerate(envs):
            if done[i]:
                continue
            obs[i], _, terminated, truncated, _ = env.step(actions[i])
            steps[i] += 1
            done[i], fell[i] = terminated or truncated, bool(terminated)
            last[i] = panel(i)
        frames.append(np.concatenate(last, axis=1))
        if all(done):
            break
    for c in cams:
        c.close()
    return frames


def render_morph(
    act: Act,
    env: ParamEnv,
    task: np.ndarray,
    path: Sequence[dict[str, float]],
    seconds: float,
    width: int = 320,
    height: int = 240,
    seed: int = 0,
) -> list[np.ndarray]:
    """Frames of one body whose shape follows `path` over `seconds` ([WL19] §5.2, Fig. 1):
    `morph_episode` seen from one distance, the tallest body's on the path."""
    order = env.task_space.names
    distance = 0.0
    for shape in path:  # the camera's distance: the tallest body's on the path
        a = np.array(task, dtype=float)
        for name, value in shape.items():
            a[order.index(name)] = value  # (names were checked against the task space)
        distance = max(distance, camera_distance(env, env.body_for(a)))
    cam = Camera(width, height, distance)
    frames: list[np.ndarray] = []
    morph_episode(
        act, env, task, path, seconds, seed,
        watch=lambda: frames.append(label(cam.frame(env), shape_label(env))),
    )  # fmt: skip
    cam.close()
    return frames
