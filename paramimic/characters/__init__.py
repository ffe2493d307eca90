"""Parametric characters: base bodies and the shape map F(B̄, b) ([WL19] §3.1)."""

from paramimic.characters.articulated import BIPED_LOWER, FISH, MANTA, QUADRUPED
from paramimic.characters.body import (
    Character,
    CharacterDef,
    ShapeParam,
    build_spec,
    compile_character,
)
from paramimic.characters.humanoid import HUMANOID
from paramimic.characters.planar import HOPPER, WALKER

CHARACTERS: dict[str, CharacterDef] = {
    c.name: c for c in (WALKER, HOPPER, HUMANOID, BIPED_LOWER, QUADRUPED, FISH, MANTA)
}


def get_character(name: str) -> CharacterDef:
    try:
        return CHARACTERS[name]
    except KeyError:
        raise KeyError(f"unknown character {name!r}; known: {sorted(CHARACTERS)}") from None


__all__ = [
    "CHARACTERS",
    "Character",
    "CharacterDef",
    "ShapeParam",
    "build_spec",
    "compile_character",
    "get_character",
]
