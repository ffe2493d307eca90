"""Parametric characters: base bodies and the shape map F(B̄, b) ([WL19] §3.1), registered once
each in `registry` (a new character: one file and one `register` line below)."""

from paramimic.characters.articulated import (
    BIPED_LOWER_REGISTRATION,
    FISH_REGISTRATION,
    MANTA_REGISTRATION,
    QUADRUPED_REGISTRATION,
)
from paramimic.characters.body import Body, ShapeParam
from paramimic.characters.humanoid import HUMANOID_REGISTRATION
from paramimic.characters.planar import HOPPER_REGISTRATION, WALKER_REGISTRATION
from paramimic.characters.registry import (
    REGISTRY,
    Character,
    Registration,
    clip_owners,
    get_character,
    register,
    registration,
)

register(WALKER_REGISTRATION)
register(HOPPER_REGISTRATION)
register(HUMANOID_REGISTRATION)
register(BIPED_LOWER_REGISTRATION)
register(QUADRUPED_REGISTRATION)
register(FISH_REGISTRATION)
register(MANTA_REGISTRATION)

__all__ = [
    "REGISTRY",
    "Body",
    "Character",
    "Registration",
    "ShapeParam",
    "clip_owners",
    "get_character",
    "register",
    "registration",
]
