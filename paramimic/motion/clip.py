"""Reference clips m0 ([L21] §3): keyframed full-body poses with frame durations.

A pose is (p0, q1, q2..qL): root position, root rotation and joint rotations. Joints are
spherical (a unit quaternion each) or revolute (one angle each). Between keyframes positions and
angles interpolate linearly and rotations by slerp, so m0(φ) is continuous in reference time φ
(seconds of the clip). Quaternions are stored scalar-last (x, y, z, w), scipy's order.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

LoopMode = Literal["wrap", "none"]


@dataclass(frozen=True)
class ClipPose:
    """Poses at n reference times: root [n, 3] and [n, 4], spherical [n, S, 4], revolute [n, R]."""

    root_position: np.ndarray
    root_quat: np.ndarray
    spherical: np.ndarray
    revolute: np.ndarray
    spherical_names: tuple[str, ...] = ()
    revolute_names: tuple[str, ...] = ()


@dataclass(frozen=True)
class Clip:
    name: str
    durations: np.ndarray  # [F] seconds from frame i to i+1 (the last is unused)
    root_position: np.ndarray  # [F, 3]
    root_quat: np.ndarray  # [F, 4] x, y, z, w
    spherical_names: tuple[str, ...]
    spherical: np.ndarray  # [F, S, 4]
    revolute_names: tuple[str, ...]
    revolute: np.ndarray  # [F, R]
    loop: LoopMode = "none"
    times: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n = len(self.durations)
        if n < 2:
            raise ValueError(f"clip {self.name!r}: needs at least 2 frames, has {n}")
        shapes = {
            "root_position": (self.root_position.shape, (n, 3)),
            "root_quat": (self.root_quat.shape, (n, 4)),
            "spherical": (self.spherical.shape, (n, len(self.spherical_names), 4)),
            "revolute": (self.revolute.shape, (n, len(self.revolute_names))),
        }
        for key, (got, want) in shapes.items():
            if got != want:
                raise ValueError(f"clip {self.name!r}: {key} has shape {got}, expected {want}")
        if np.any(self.durations[:-1] <= 0):
            raise ValueError(f"clip {self.name!r}: frame durations must be positive")
        times = np.concatenate([[0.0], np.cumsum(self.durations[:-1])])
        object.__setattr__(self, "times", times)
        for q in (self.root_quat, self.spherical):
            norms = np.linalg.norm(q, axis=-1, keepdims=True)
            q /= norms  # the files round to 10 digits; keep every quaternion unit

    @property
    def num_frames(self) -> int:
        return len(self.durations)

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.spherical_names + self.revolute_names

    def sample(self, phi: np.ndarray | float) -> ClipPose:
        """m0(φ) at reference times φ (seconds): linear in positions and angles, slerp in
        rotations. "wrap" clips repeat, moving the root forward by one cycle's horizontal
        displacement per repetition; "none" clips hold their last frame."""
        phi = np.atleast_1d(np.asarray(phi, np.float64))
        T = self.duration
        if self.loop == "wrap":
            cycles = np.floor(phi / T)
            local = phi - cycles * T
        else:
            cycles = np.zeros_like(phi)
            local = np.clip(phi, 0.0, T)
        k = np.clip(np.searchsorted(self.times, local, side="right") - 1, 0, self.num_frames - 2)
        u = (local - self.times[k]) / (self.times[k + 1] - self.times[k])
        root = _lerp(self.root_position[k], self.root_position[k + 1], u[:, None])
        drift = self.root_position[-1] - self.root_position[0]
        drift[2] = 0.0  # vertical position does not accumulate over cycles (Z up)
        root = root + cycles[:, None] * drift
        return ClipPose(
            root_position=root,
            root_quat=_slerp(self.root_quat[k], self.root_quat[k + 1], u),
            spherical=_slerp(self.spherical[k], self.spherical[k + 1], u[:, None]),
            revolute=_lerp(self.revolute[k], self.revolute[k + 1], u[:, None]),
            spherical_names=self.spherical_names,
            revolute_names=self.revolute_names,
        )


def _lerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    return a + (b - a) * u


def _slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions [..., 4], u broadcast over [...]."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where((dot < 0)[..., None], -q1, q1)  # take the short way round
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-6
    safe = np.where(small, 1.0, sin)
    w0 = np.where(small, 1.0 - u, np.sin((1.0 - u) * theta) / safe)
    w1 = np.where(small, u, np.sin(u * theta) / safe)
    q = w0[..., None] * q0 + w1[..., None] * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# --- DeepMimic clips -------------------------------------------------------------------------

# Joint order of a DeepMimic humanoid3d frame after duration, root position and root rotation:
# (name, number of values): 4 for a spherical joint (w, x, y, z), 1 for a revolute one.
DEEPMIMIC_JOINTS: tuple[tuple[str, int], ...] = (
    ("chest", 4),
    ("neck", 4),
    ("right_hip", 4),
    ("right_knee", 1),
    ("right_ankle", 4),
    ("right_shoulder", 4),
    ("right_elbow", 1),
    ("left_hip", 4),
    ("left_knee", 1),
    ("left_ankle", 4),
    ("left_shoulder", 4),
    ("left_elbow", 1),
)
DEEPMIMIC_FRAME = 1 + 3 + 4 + sum(n for _, n in DEEPMIMIC_JOINTS)  # 44
# Y-up file world -> our Z-up world: a +90° rotation about x, applied to the root only
Y_UP_TO_Z_UP = Rotation.from_rotvec([np.pi / 2, 0.0, 0.0])


MAX_FRAME_SECONDS = 10.0  # a frame longer than this is no motion capture
MAX_CLIP_SECONDS = 600.0  # a clip is a skill or a gait cycle, not a recording session


def load_deepmimic(path: str | Path, name: str | None = None, text: str | None = None) -> Clip:
    """A DeepMimic humanoid3d clip: {"Loop": "wrap"|"none", "Frames": [[44 numbers], ...]},
    read from `path`, or parsed from `text` (the file's content, carried with a run; `path`
    then only names it).

    The root moves into our Z-up world; joint rotations stay local to their parents, so they
    apply unchanged to a skeleton built in the file's own frames."""
    path = Path(path)
    try:
        raw = json.loads(path.read_text() if text is None else text)
        frames = np.asarray(raw["Frames"], np.float64)
    except RecursionError:  # JSON nested deeper than Python's parser goes
        raise ValueError(f"{path}: not a DeepMimic clip: nested too deep") from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{path}: not a DeepMimic clip: {e}") from e
    if frames.ndim != 2 or frames.shape[1] != DEEPMIMIC_FRAME:
        raise ValueError(
            f"{path}: frames must have {DEEPMIMIC_FRAME} numbers each, got shape {frames.shape}"
        )
    if not np.isfinite(frames).all():
        bad = np.argwhere(~np.isfinite(frames))[0]
        raise ValueError(f"{path}: frame {bad[0]} holds a non-finite number (column {bad[1]})")
    if len(frames) < 2:
        raise ValueError(f"{path}: a clip needs at least 2 frames, got {len(frames)}")
    if (frames[:-1, 0] <= 0).any():
        k = int(np.argmax(frames[:-1, 0] <= 0))
        raise ValueError(f"{path}: frame {k} has a non-positive duration {frames[k, 0]}")
    if (frames[:, 0] > MAX_FRAME_SECONDS).any() or frames[:-1, 0].sum() > MAX_CLIP_SECONDS:
        raise ValueError(
            f"{path}: frames last at most {MAX_FRAME_SECONDS:g} s each and a clip at most "
            f"{MAX_CLIP_SECONDS:g} s; this one lasts {frames[:-1, 0].sum():g} s"
        )
    loop = raw.get("Loop", "none")
    if loop not in ("wrap", "none"):
        raise ValueError(f"{path}: Loop must be 'wrap' or 'none', got {loop!r}")
    position = Y_UP_TO_Z_UP.apply(frames[:, 1:4])
    root = Y_UP_TO_Z_UP * Rotation.from_quat(frames[:, 4:8], scalar_first=True)
    spherical, revolute, s_names, r_names = [], [], [], []
    col = 8
    for joint, width in DEEPMIMIC_JOINTS:
        values = frames[:, col : col + width]
        col += width
        if width == 4:
            s_names.append(joint)
            spherical.append(Rotation.from_quat(values, scalar_first=True).as_quat())
        else:
            r_names.append(joint)
            revolute.append(values[:, 0])
    return Clip(
        name=name or path.stem,
        durations=frames[:, 0].copy(),
        root_position=position,
        root_quat=root.as_quat(),
        spherical_names=tuple(s_names),
        spherical=np.stack(spherical, axis=1),
        revolute_names=tuple(r_names),
        revolute=np.stack(revolute, axis=1),
        loop=loop,
    )
