"""The numbers of a body that its shape b sets, apart from its structure ([WL19] §3.1).

F(B̄, b) changes only dimensions: where each body sits in its parent, the size, position and
mass of each geom, where each site sits. A builder states them once as `Dims`; it builds its
MjSpec from them, and `Reshaper` writes them into one spec kept per character, so that a new
shape costs an edit and a compile instead of a new spec (MuJoCo's way: edit the spec,
compile again). Both paths give the same model (tests/test_dimensions.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np


@dataclass
class Dims:
    bodies: dict[str, list[float]]  # body name -> position in its parent
    geoms: dict[str, dict[str, Any]]  # geom name -> attributes set by the shape (size, pos, ...)
    sites: dict[str, list[float]]  # site name -> position in its body
    legs: np.ndarray  # [L] leg lengths (reward normalization, [WL19] Table 1)
    hip_height: float  # root height when standing straight on the ground (or swimming)
    lengths: dict[str, float] = field(default_factory=dict)  # segment lengths


def apply_dims(spec: mujoco.MjSpec, dims: Dims) -> None:
    """Write `dims` into a spec of the same structure."""
    for name, pos in dims.bodies.items():
        spec.body(name).pos = pos
    for name, attrs in dims.geoms.items():
        geom = spec.geom(name)
        for key, value in attrs.items():
            setattr(geom, key, value)
    for name, pos in dims.sites.items():
        spec.site(name).pos = pos


def shape_with_defaults(definition, shape: dict[str, float] | None) -> dict[str, float]:
    """Fill missing shape parameters with 1.0; reject names the character does not have."""
    full = definition.default_shape()
    for name, value in (shape or {}).items():
        if name not in full:
            raise KeyError(
                f"character {definition.name!r} has no shape parameter {name!r}; "
                f"it has {sorted(full)}"
            )
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"shape parameter {name!r} must be a positive number, got {value}")
        full[name] = float(value)
    return full


class Reshaper:
    """F(B̄, b) for one character by editing one spec: `reshaper(shape)` is the same Body as
    `character.compile(shape)`, at the cost of a compile."""

    def __init__(self, character) -> None:
        self.character = character
        base = character.default_shape()
        self.spec = character.spec(base)
        self.default_timestep = self.spec.option.timestep
        self.template = character.compile(base)  # indices: the same for every shape

    def __call__(self, shape: dict[str, float] | None = None, timestep: float | None = None):
        """The Body of `shape`, simulated at `timestep` (s; default: the character's)."""
        shape = shape_with_defaults(self.character, shape)
        dims = self.character.dimensions(shape)
        apply_dims(self.spec, dims)
        self.spec.option.timestep = timestep or self.default_timestep
        model = self.spec.compile()
        return replace(
            self.template,
            shape=shape,
            model=model,
            leg_lengths=np.asarray(dims.legs, np.float64),
            mass=float(model.body_subtreemass[self.template.root_body_id]),
            hip_height=float(dims.hip_height),
            segment_lengths=dict(dims.lengths),
        )
