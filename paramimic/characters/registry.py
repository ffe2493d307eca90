"""The character registry: every character registers once, and everything else reads it.

A `Registration` holds a character (anything that satisfies the `Character` protocol: a builder
of F(B̄, b) with its shape parameters and capabilities), the [WL19] procedural gait it walks or
swims with (for `ParamEnv`), and the [L21] clips it can imitate (for `SkillEnv`). Config
validation, both environments, the gymnasium registrations (`paramimic.envs`) and the API's
character info all look characters up here. Adding a character is one file that defines it and
one `register(...)` line (`paramimic/characters/__init__.py`, or `paramimic.envs.register` at
run time, which also makes its gymnasium envs).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Protocol, runtime_checkable

import mujoco
import numpy as np

from paramimic.characters.body import Body, Joint, ShapeParam
from paramimic.characters.dimensions import Dims
from paramimic.motion.clip import Clip, ClipPose
from paramimic.motion.procedural import SinusoidalMotion


@runtime_checkable
class Character(Protocol):
    """A base character B̄ and its shape map F(B̄, b) ([WL19] §3.1)."""

    name: str
    shape_params: tuple[ShapeParam, ...]  # b, each with the range it is meant for
    end_effectors: tuple[str, ...]  # bodies with a site `{name}_end`
    feet: tuple[str, ...]  # contact sites `{foot}_c0..3` ([WL19] Eq. 1 points)

    @property
    def joints(self) -> tuple[Joint, ...]: ...  # actuated hinges, in actuator order

    @property
    def root(self) -> str: ...

    @property
    def fall_bodies(self) -> tuple[str, ...]: ...  # their contact with the ground is a fall

    @property
    def planar(self) -> bool: ...  # root slides in x, z and pitches; else a free root

    @property
    def swims(self) -> bool: ...  # moves in MuJoCo's fluid model, no floor and no falls

    @property
    def legs(self) -> tuple[tuple[str, ...], ...]: ...  # hip-to-sole chains (retargeting); ()

    def param_names(self) -> tuple[str, ...]: ...

    def default_shape(self) -> dict[str, float]: ...

    def dimensions(self, shape: dict[str, float]) -> Dims: ...  # what b sets (all of b given)

    def spec(self, shape: dict[str, float] | None = None) -> mujoco.MjSpec: ...  # F(B̄, b)

    def compile(self, shape: dict[str, float] | None = None) -> Body: ...


@runtime_checkable
class PosesClips(Protocol):
    """A character that can imitate clips maps a clip's poses to its qpos."""

    def pose_qpos(self, body: Body, pose: ClipPose) -> np.ndarray: ...


@dataclass(frozen=True)
class Registration:
    """One character and the motions it supports."""

    character: Character
    gait: SinusoidalMotion | None = None  # [WL19] §5.3 reference gait (ParamEnv)
    clips: Mapping[str, Callable[[], Clip]] = field(default_factory=dict)  # [L21] (SkillEnv)
    # reads a user's clip file for this character (e.g. DeepMimic's humanoid3d format), or
    # parses its content (`text=`); None: only the built-in clips
    clip_file: Callable[..., Clip] | None = None
    # extra gymnasium envs: id stem -> `make_env` kwargs ("task", "config"); every
    # character also gets `paramimic/<Name>-v0` and one env per clip
    envs: Mapping[str, Mapping] = field(default_factory=dict)
    # the default physics rate (Hz): what benchmarks/physics_rate.py shows the body needs
    physics_hz: int = 600
    # [WL19] Table 3, w1..w6 of Eq. 4-7 (pose, joint velocity, end effector, COM velocity,
    # direction, torque): the biped-lower row unless the paper gives the body its own
    reward_weights: tuple[float, float, float, float, float, float] = (5.0, 2.0, 2.0, 1.0, 1.0, 1.0)

    @property
    def name(self) -> str:
        return self.character.name

    def load_clip(self, clip: str, texts: Mapping[str, str] | None = None) -> Clip:
        """A built-in clip by name, or a clip file (a path) in the character's format, from
        `texts` (path -> the file's content, carried with a run) when it is there; a file that
        cannot be read or does not fit raises ValueError naming the problem."""
        if clip in self.clips:
            return self.clips[clip]()
        if texts and clip in texts and self.clip_file is not None:
            return self.clip_file(Path(clip), text=texts[clip])
        path = Path(clip).expanduser()
        if self.clip_file is None or not path.suffix and not path.exists():
            files = "" if self.clip_file is None else ", or a clip file"
            raise ValueError(
                f"clip {clip!r} does not fit {self.name!r}: it has {sorted(self.clips)}{files}"
            )
        if not path.is_file():
            raise ValueError(f"clip file {clip} does not exist")
        return self.clip_file(path)

    def shape_ranges(self, scale: float = 1.0) -> dict[str, tuple[float, float]]:
        """The documented family's shape ranges (`shape_space: full`) shrunk toward the base body
        by `scale`: [1 - s(1 - lo), 1 + s(hi - 1)] (1: as documented; 0: the base body alone)."""
        return {
            p.name: (1 - scale * (1 - p.low), 1 + scale * (p.high - 1))
            for p in self.character.shape_params
            if p.in_full
        }

    @property
    def title(self) -> str:
        """The CamelCase name of gymnasium ids: biped_lower -> BipedLower."""
        return camel(self.name)

    def info(self) -> dict:
        """What a reader of the run (the API, a dashboard) knows of the character: JSON."""
        c = self.character
        return {
            "name": c.name,
            "planar": c.planar,
            "swims": c.swims,
            "shape_params": {p.name: [p.low, p.high] for p in c.shape_params},
            "joints": [j.name for j in c.joints],
            "gait": self.gait is not None,
            "clips": sorted(self.clips),
            "envs": sorted(self.env_specs()),
            "physics_hz": self.physics_hz,
            "reward_weights": list(self.reward_weights),
        }

    def env_specs(self) -> dict[str, dict]:
        """Gymnasium env id -> kwargs of `paramimic.envs.make_env` for this character: the
        base env (its gait, or else its first clip), one env per clip, and the extra ones."""
        specs: dict[str, dict] = {}
        if self.gait is not None:
            specs[f"paramimic/{self.title}-v0"] = {"character": self.name}
        for i, clip in enumerate(self.clips):
            stem = camel(clip)
            stem = stem if stem.startswith(self.title) else self.title + stem
            kwargs = {"character": self.name, "config": {"clip": clip}}
            specs[f"paramimic/{stem}-v0"] = kwargs
            if i == 0 and self.gait is None:
                specs[f"paramimic/{self.title}-v0"] = kwargs
        for stem, kwargs in self.envs.items():
            specs[f"paramimic/{stem}-v0"] = {"character": self.name, **kwargs}
        return specs


def camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


_REGISTRY: dict[str, Registration] = {}
REGISTRY: Mapping[str, Registration] = MappingProxyType(_REGISTRY)  # read-only view


def register(registration: Registration) -> Registration:
    """Add a character. Its gait must drive its joints in order; a name is registered once
    (registering the same registration again is a no-op)."""
    c = registration.character
    if not isinstance(c, Character):
        raise TypeError(f"{c!r} does not satisfy the Character protocol")
    known = _REGISTRY.get(c.name)
    if known is not None and known is not registration:
        raise ValueError(f"character {c.name!r} is already registered")
    joints = tuple(j.name for j in c.joints)
    gait = registration.gait
    if gait is not None and gait.joints != joints:
        raise ValueError(f"{c.name}: gait joints {gait.joints} != the character's {joints}")
    if registration.clips and not isinstance(c, PosesClips):
        raise TypeError(f"{c.name}: a character with clips needs pose_qpos (PosesClips)")
    _REGISTRY[c.name] = registration
    return registration


def registration(name: str) -> Registration:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown character {name!r}; known: {sorted(_REGISTRY)}") from None


def get_character(name: str) -> Character:
    return registration(name).character


def clip_owners() -> dict[str, tuple[str, ...]]:
    """Every registered clip name -> the characters that can imitate it."""
    owners: dict[str, list[str]] = {}
    for reg in _REGISTRY.values():
        for clip in reg.clips:
            owners.setdefault(clip, []).append(reg.name)
    return {k: tuple(v) for k, v in owners.items()}
